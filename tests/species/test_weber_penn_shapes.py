"""Weber-Penn shape ratios: known values of the paper's shapes."""
import numpy as np
import pytest

from species.weber_penn.shapes import auto_taper, shape_ratio


@pytest.mark.parametrize("shape, ratio, expected", [(0, 1.0, 1.0), (0, 0.0, 0.05), (1, 0.5, 1.0), (3, 0.3, 1.0),
                                                    (4, 0.0, 0.5), (5, 0.7, 1.0), (6, 0.0, 1.0), (7, 0.7, 1.0),
                                                    (7, 0.0, 0.5), (10, 0.0, 1.0)])
def test_shape_ratio_known_values(shape, ratio, expected):
    assert float(shape_ratio(shape, ratio)) == pytest.approx(expected)


def test_custom_shape_runs_from_base_to_top_values():
    custom = [0.2, 1.0, 0.4, 0.6]
    assert float(shape_ratio(8, 1.0, custom)) == pytest.approx(0.2)  # ratio 1 = the base
    assert float(shape_ratio(8, 0.0, custom)) == pytest.approx(0.6)  # ratio 0 = the top
    assert float(shape_ratio(8, 0.6, custom)) == pytest.approx(1.0)  # the peak at custom[2]


def test_envelope_shape_is_zero_outside_and_peaks_at_one():
    r = np.linspace(0, 1, 101)
    values = shape_ratio(9, r, None, 0.6, 0.5, 0.001)
    assert values[0] == 0 and values[-1] == 0
    assert values.max() == pytest.approx(1.0, abs=0.02)


def test_auto_taper_keeps_the_last_level_taper():
    taper = auto_taper([1, 0.3, 0.6, 0.45], [1, 1, 1, 1], 7, 4, 3, [0.5, 1, 0.3, 0.5])
    # per-level products of length x shape(0): 1, 0.15, 0.045; each divided by the sum from its level down
    assert taper[:3] == pytest.approx([1 / 1.195, 0.15 / 0.195, 1.0])
