"""Where a figure's texts go, and whether they can be read: legends above the axes that fit the figure's width,
tick labels thinned or turned until none overlaps, captions wrapped, and the counts of what still collides or
runs off the figure (what ``inspect`` reports, so tests check a figure from what was drawn).

Every check lays the figure out with ``draw_without_rendering``: the texts are placed and measured by the
renderer that saves the PNG, but no pixel is painted (a figure is laid out up to a dozen times and painted
once, when saved; the PNGs and what ``inspect`` reports are the same, byte for byte)."""

from __future__ import annotations

import textwrap

LEGEND_PT = 7.0
CAPTION_PT = 8.0
MIN_TICK_PT = 6.0


def short_label(label: str, limit: int = 28) -> str:
    """A category label short enough to read under a bar (the full name is in the CSV tables)."""
    if len(label) <= limit:
        return label
    keep = (limit - 1) // 2
    return label[:keep] + "…" + label[-(limit - 1 - keep):]


def legend_above(ax, width_in: float, handles: list | None = None, labels: list[str] | None = None,
                 columns: int | None = None, chars: int | None = None) -> None:
    """The legend above the axes, in as many columns as fit the figure's width, labels shortened to
    fit (the full names are in the CSV tables): inside the axes it would hide data, beside them it
    would squeeze a narrow figure.  :func:`fit_legends` narrows it further once laid out."""
    if handles is None or labels is None:
        handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    char_pt = LEGEND_PT * 0.62
    room_pt = width_in * 72 * 0.82
    chars = chars or max(10, int((room_pt - 28) / char_pt))
    shown = [short_label(label, chars) for label in labels]
    column_pt = max(len(label) for label in shown) * char_pt + 28
    if columns is None:
        columns = max(1, min(len(shown), int(room_pt // column_pt)))
    ax.legend(handles, shown, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=columns, fontsize=LEGEND_PT,
              frameon=False, borderaxespad=0.0, handlelength=1.6, columnspacing=1.0)
    ax._hilgate_legend = (width_in, handles, labels, columns, chars)


def fit_legends(fig) -> bool:
    """A legend that runs off the figure takes fewer columns (more rows), then shorter labels, until it
    fits."""
    changed = False
    fig.draw_without_rendering()
    for ax in fig.axes:
        made = getattr(ax, "_hilgate_legend", None)  # (by name: matplotlib's axes carry our mark)
        while made is not None and ax.get_legend() is not None and not inside(fig, ax.get_legend()):
            width_in, handles, labels, columns, chars = made
            if columns > 1:
                columns -= 1
            elif chars > 8:
                chars = max(8, chars - 4)
            else:
                break
            legend_above(ax, width_in, handles, labels, columns, chars)
            made = ax._hilgate_legend
            changed = True
            fig.draw_without_rendering()
    return changed


def _overlapping(boxes: list) -> bool:
    for a, b in zip(boxes, boxes[1:]):
        if a.x0 < b.x1 - 1 and b.x0 < a.x1 - 1 and a.y0 < b.y1 - 1 and b.y0 < a.y1 - 1:
            return True
    return False


def _shown_labels(axis) -> list:
    """The tick labels drawn: visible, with text, and at a tick inside the axis' view (matplotlib
    keeps labels for ticks just outside it, which are not drawn)."""
    low, high = sorted(axis.get_view_interval())
    slack = (high - low) * 1e-9
    return [label for loc, label in zip(axis.get_majorticklocs(), axis.get_majorticklabels())
            if label.get_visible() and label.get_text() and low - slack <= loc <= high + slack]


def _tick_boxes(axis, renderer) -> list:
    boxes = [label.get_window_extent(renderer) for label in _shown_labels(axis)]
    return sorted(boxes, key=lambda b: (b.x0, b.y0))


def _clear_corners(ax, renderer) -> bool:
    """An x tick label at the axes' edge may run into the y tick labels beside it: it is hidden."""
    ys = _tick_boxes(ax.yaxis, renderer)
    hidden = False
    for label in _shown_labels(ax.xaxis):
        box = label.get_window_extent(renderer)
        if any(box.x0 < y.x1 - 1 and y.x0 < box.x1 - 1 and box.y0 < y.y1 - 1 and y.y0 < box.y1 - 1 for y in ys):
            label.set_visible(False)
            hidden = True
    return hidden


def legible(fig) -> tuple[bool, int]:
    """Thin or turn the tick labels of every axis until none overlaps another; returns whether it
    changed any, and how many axes still have overlapping labels (0, unless a figure is absurdly small)."""
    from matplotlib.ticker import FixedLocator, MaxNLocator

    changed, still = False, 0
    fig.draw_without_rendering()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for label in axis.get_ticklabels():
                if label.get_fontsize() < MIN_TICK_PT:
                    label.set_fontsize(MIN_TICK_PT)
            tries = 0
            while _overlapping(_tick_boxes(axis, renderer)) and tries < 12:
                tries += 1
                changed = True
                locator = axis.get_major_locator()
                if isinstance(locator, FixedLocator) or axis.get_scale() == "log":
                    labels = _shown_labels(axis)
                    if axis is ax.xaxis and tries == 1:
                        for label in labels:  # named categories: upright first
                            label.set_rotation(90)
                            label.set_horizontalalignment("center")
                    else:
                        for label in labels[1::2]:  # then every other one
                            label.set_visible(False)
                else:
                    count = max(2, len([t for t in axis.get_ticklabels() if t.get_text()]) // 2)
                    axis.set_major_locator(MaxNLocator(nbins=count, min_n_ticks=1))
                fig.draw_without_rendering()
            still += _overlapping(_tick_boxes(axis, renderer))
        if _clear_corners(ax, renderer):
            changed = True
            fig.draw_without_rendering()
    return changed, still


def collisions(fig, caption) -> int:
    """Pairs of texts of different kinds that overlap: tick labels of one axis, axis labels, legends,
    the caption (when drawn)."""
    renderer = fig.canvas.get_renderer()
    groups: list[list] = [[caption.get_window_extent(renderer)]] if caption is not None else []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            groups.append(_tick_boxes(axis, renderer))
            if axis.label.get_text():
                groups.append([axis.label.get_window_extent(renderer)])
        legend = ax.get_legend()
        if legend is not None:
            groups.append([legend.get_window_extent(renderer)])
    hits = 0
    for i, first in enumerate(groups):
        for second in groups[i + 1:]:
            hits += any(a.x0 < b.x1 - 1 and b.x0 < a.x1 - 1 and a.y0 < b.y1 - 1 and b.y0 < a.y1 - 1
                        for a in first for b in second)
    return hits


def outside(fig) -> int:
    """Texts (tick labels, axis labels, legends) that run off the figure."""
    renderer = fig.canvas.get_renderer()
    count = 0
    for ax in fig.axes:
        texts = _shown_labels(ax.xaxis) + _shown_labels(ax.yaxis) + [ax.xaxis.label, ax.yaxis.label]
        legend = ax.get_legend()
        count += sum(1 for t in texts if t.get_text() and not inside(fig, t))
        count += legend is not None and not inside(fig, legend)
    return count


def caption_lines(caption: str, width_in: float) -> list[str]:
    per_line = max(24, int(width_in * 72 / (CAPTION_PT * 0.62)))
    lines = textwrap.wrap(caption, per_line) or [""]
    if len(lines) > 10:
        lines = lines[:9] + [textwrap.shorten(" ".join(lines[9:]), per_line, placeholder=" …")]
    return lines


def inside(fig, artist) -> bool:
    renderer = fig.canvas.get_renderer()
    box, frame = artist.get_window_extent(renderer), fig.bbox
    return frame.x0 - 1 <= box.x0 and box.x1 <= frame.x1 + 1 and frame.y0 - 1 <= box.y0 and box.y1 <= frame.y1 + 1
