"""Where the window's panels go, so that every panel fits the window it opens in.

GGUI (Dear ImGui) gives a sub-window a scroll bar when its content is taller than the window
and clips a line wider than it. Here each panel is a column of *sections*; a section's height
is counted before it is drawn (``RowCounter`` stands in for the GUI and adds up the rows its
widgets would take), and a column that would not fit closes sections, the least recently
opened first, until it does. A closed section shows its header only (a checkbox that opens
it); its keys keep working. Text is wrapped to the column's width in characters.

The row heights are GGUI's default style (ProggyClean 13 px, item spacing 4 px), read off
screenshots under Xvfb; tests/test_app.py checks on screenshots at 1280 x 800 and 1366 x 768
that no panel grows a scroll bar.
"""
from dataclasses import dataclass, field

TEXT_ROW = 17        # px: a line of text
WIDGET_ROW = 23      # px: a button, checkbox or slider
CHROME = 40          # px: title bar (19), padding above and below (8 + 8), 5 to spare
CHAR = 7             # px: one character of the (monospaced) default font
PAD = 8              # px: the window's padding left and right
GAP = 4              # px: between two sub-windows of a column


class RowCounter:
    """A stand-in for ``window.get_gui()`` that draws nothing and adds up the height of what
    would be drawn; every widget returns the value it was given (nothing changes)."""

    def __init__(self):
        self.height = 0

    def text(self, _text, color=None):
        self.height += TEXT_ROW

    def button(self, _label):
        self.height += WIDGET_ROW
        return False

    def checkbox(self, _label, value):
        self.height += WIDGET_ROW
        return value

    def slider_float(self, _label, value, *_range):
        self.height += WIDGET_ROW
        return value

    slider_int = slider_float


def measure(draw):
    """The height in pixels that ``draw(gui)`` takes."""
    counter = RowCounter()
    draw(counter)
    return counter.height


def panel_height(content):
    """A sub-window's height in pixels for ``content`` pixels of rows."""
    return CHROME + max(content - 4, 0)       # no item spacing after the last row


def wrap_width(width_px):
    """Characters per line in a sub-window ``width_px`` wide."""
    return max(16, (width_px - 2 * PAD) // CHAR - 1)


@dataclass
class Accordion:
    """Which sections of a column are open. ``wanted`` lists the sections the user opened, the
    most recently opened last; ``fit`` shows as many of them, newest first, as the column's
    height allows (a section closed for room opens again when the room comes back)."""
    names: list
    wanted: list = field(default_factory=list)

    def __post_init__(self):
        if not self.wanted:
            self.wanted = list(reversed(self.names))    # the first section closes last
        self.shown = list(self.wanted)

    def is_open(self, name):
        return name in self.shown

    def toggle(self, name):
        """Close a shown section, or open one (it is then kept open before any other)."""
        if name in self.wanted:
            self.wanted.remove(name)
        if name not in self.shown:
            self.wanted.append(name)
        self.shown = list(self.wanted)

    def fit(self, heights, headers, available):
        """Show the most recently opened sections that fit: ``heights`` maps each section to
        its open content height, ``headers`` the px taken whatever is open, ``available`` the
        px the column has. The newest stays open even if it alone is too tall (its panel then
        scrolls). Returns the content height."""
        self.shown = list(self.wanted)
        def total():
            return headers + sum(heights[n] for n in self.shown)
        while total() > available and len(self.shown) > 1:
            self.shown.pop(0)
        return total()
