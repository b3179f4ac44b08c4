"""pipeline/report/figures.py: fixed margins in inches, PNG output of the requested size, atomic files."""
import io

import pytest
from PIL import Image

from pipeline.report import figures
from pipeline.report.figures import figure, png_bytes, save_png


@pytest.mark.parametrize("rows, cols, size", [(1, 3, (12.5, 3.4)), (2, 3, (12.6, 6.0)), (1, 2, (10.0, 4.0))])
def test_axes_sit_at_the_fixed_margins(rows, cols, size):
    fig, axes = figure(rows, cols, size)
    assert axes.shape == (rows, cols)
    width, height = size
    boxes = [[ax.get_position() for ax in row] for row in axes]
    assert boxes[0][0].x0 * width == pytest.approx(figures.LEFT_IN)
    assert (1 - boxes[0][-1].x1) * width == pytest.approx(figures.RIGHT_IN)
    assert (1 - boxes[0][0].y1) * height == pytest.approx(figures.TOP_IN)
    assert boxes[-1][0].y0 * height == pytest.approx(figures.BOTTOM_IN)
    if cols > 1:
        assert (boxes[0][1].x0 - boxes[0][0].x1) * width == pytest.approx(figures.COLUMN_GAP_IN)
    if rows > 1:
        assert (boxes[0][0].y0 - boxes[1][0].y1) * height == pytest.approx(figures.ROW_GAP_IN)


def test_png_has_the_figure_size_at_the_dpi(tmp_path):
    fig, axes = figure(1, 2, (10.0, 4.0))
    axes[0, 0].plot([0, 1], [1, 0])
    with Image.open(io.BytesIO(png_bytes(fig, dpi=90))) as im:
        assert im.size == (900, 360)
    path = save_png(fig, tmp_path / "sub" / "f.png")
    with Image.open(path) as im:
        assert im.size == (1000, 400)  # the figure's own dpi, 100
    assert sorted(p.name for p in path.parent.iterdir()) == ["f.png"]  # no partial file left


def test_labels_of_the_reports_kind_fit_inside_the_figure():
    """Six-character tick labels, an axis label and a title per axes (as the report's plots have) are
    not clipped by the fixed margins and do not run into the neighbouring axes."""
    fig, axes = figure(2, 3, (12.6, 6.0))
    for ax in axes.ravel():
        ax.plot([0, 135], [0, 640_000])
        ax.set(xlabel="frame (dotted: K)", ylabel="N_frame (photons per frame)", title="N_frame per segment")
    renderer = fig.canvas.get_renderer()
    page = fig.bbox
    boxes = [[ax.get_tightbbox(renderer) for ax in row] for row in axes]
    for row in boxes:
        for box in row:
            assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1
        for left, right in zip(row, row[1:]):  # neighbours' labels do not overlap
            assert left.x1 <= right.x0
    for upper, lower in zip(boxes, boxes[1:]):
        assert all(lo.y1 <= up.y0 for up, lo in zip(upper, lower))
