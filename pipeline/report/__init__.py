"""What a render reports: OUT/report.html, its figures and tables (Table 2), what was skipped and why."""
