"""Characters get distinct colours, up to 80 of them, the same in the 3D view and the plots (issue #28).

The relay of lesson 05 drew eight characters with a cycle of 8-10 colours and a
legend repeating two names eight times.  ``scene.character_colors`` gives
tab20 (less its light grey, lost on the ground grid) and then colours chosen far apart in CIELAB; here the CIE76 colour
difference of every pair of the first 80 is computed with numpy and must be
above :data:`MIN_DELTA_E` (a difference of about 2.3 is just noticeable;
tab20's own closest pair, light blue and light purple, is 16.6 apart).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from mocaplab.widgets.scene import TAB20, character_colors, srgb_to_lab

#: Smallest CIE76 difference allowed between two characters' colours.
MIN_DELTA_E = 15.0
#: Smallest CIE76 difference between a character and the page (white) or the ground grid (#bbbbbb).
MIN_DELTA_E_BACKGROUND = 15.0


def _pairwise(lab: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(lab[:, None, :] - lab[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return d


def test_srgb_to_lab_matches_published_values():
    # CIELAB of sRGB primaries and greys under D65 (the standard's reference values, to 0.01)
    lab = srgb_to_lab(["#ffffff", "#000000", "#ff0000", "#00ff00", "#0000ff", "#808080"])
    expected = [
        [100.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [53.24, 80.09, 67.20],
        [87.73, -86.18, 83.18],
        [32.30, 79.19, -107.86],
        [53.59, 0.0, 0.0],
    ]
    assert np.allclose(lab, expected, atol=0.01)
    assert np.allclose(srgb_to_lab(np.array([[1.0, 0.0, 0.0]])), lab[2:3]), "hex strings and floats agree"
    with pytest.raises(ValueError, match="#rrggbb"):
        srgb_to_lab(["red"])


def test_eighty_characters_are_pairwise_distinguishable():
    colors = character_colors(80)
    assert len(colors) == 80 and all(re.fullmatch(r"#[0-9a-f]{6}", c) for c in colors)
    lab = srgb_to_lab(colors)
    d = _pairwise(lab)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    assert d.min() > MIN_DELTA_E, f"characters {i} and {j} ({colors[i]}, {colors[j]}) differ by only {d.min():.1f}"
    backgrounds = srgb_to_lab(["#ffffff", "#f2f2f2", "#bbbbbb"])
    far = np.linalg.norm(lab[:, None, :] - backgrounds[None], axis=-1).min()
    assert far > MIN_DELTA_E_BACKGROUND, f"a character's colour is {far:.1f} from the page or the ground"


def test_the_first_colours_are_tab20_and_a_colour_does_not_depend_on_how_many():
    assert character_colors(19) == [c for c in TAB20 if c != "#c7c7c7"], "tab20 less the grey of the ground grid"
    assert character_colors(3) == ["#1f77b4", "#ff7f0e", "#2ca02c"], "two or three characters look as they did"
    assert character_colors(161)[:80] == character_colors(80) == character_colors(100)[:80]
    assert len(set(character_colors(161))) == 161
    assert character_colors(0) == []
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="`n`"):
            character_colors(bad)


def test_a_cycle_of_ten_would_fail_the_check():
    # the check bites: the old tab10 cycle repeated colours from the 11th character on
    cycled = [TAB20[k % 10] for k in range(80)]
    assert _pairwise(srgb_to_lab(cycled)).min() < MIN_DELTA_E


def test_viewer_and_plots_use_the_same_colours_and_the_legend_is_grouped(cmu, monkeypatch):
    from mocaplab.widgets.path_editor import PathEditor
    from mocaplab.widgets.viewer import MotionViewer

    a, b = cmu("16_15")[:40], cmu("02_01")[:40]
    relay = [a, b] * 6
    v = MotionViewer(relay, backend="static", window_size=(160, 120))
    try:
        shown = [c.color for c in v.characters]
        assert shown == character_colors(12) and len(set(shown)) == 12
        legend = v.legend_html()
        assert legend.count("16_15") == 1 and legend.count("02_01") == 1, "each name once"
        assert legend.count("&#9679;") == 12, "one dot per character"
        assert "16_15 ×6" in legend
        groups = re.findall(r"class='mocaplab-legend-group'.*?</span> ", legend)
        assert len(groups) == 2
        assert all(c in groups[0] for c in character_colors(12)[0::2]), "16_15's dots are its characters' colours"
        # with distinct names the legend is one entry per character, as before
        v2 = MotionViewer([a, b], labels=["A", "B"], backend="static", window_size=(160, 120))
        assert "×" not in v2.legend_html() and v2.legend_html().count("&#9679;") == 2
        v2.close()
    finally:
        v.close()
    pe = PathEditor([a.resample(30), b.resample(30)], viewer=False)
    assert pe.colors == character_colors(2), "the path editor's plot uses the viewer's colours"
