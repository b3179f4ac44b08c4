"""Built-in scenes, generated procedurally and written as real glTF 2.0 files."""
