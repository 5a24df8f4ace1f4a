"""The sweep's charts show what was swept: each heat-map cell is centred on its grid point (issue 22.9: the cells
sat half a cell off, their edges on the grid values), and each cell's colour is that point's value."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from tuner.studies.sweep import Axis, Point, grid_points, heat_map_figure

pytestmark = pytest.mark.quick


def _points(axes):
    # a made-up lap time per grid point, distinct everywhere, so a shifted or transposed map would show
    return [Point(values=v, lap_times_s=(10 + v[axes[0].address] + 100 * v[axes[1].address],), laps=1, failures=(),
                  max_cross_track_m=0.0, energy_j=1.0) for v in grid_points(axes)]


@pytest.mark.parametrize("a, b", [(Axis("motion.mu", 0.5, 1.0, 3), Axis("control.v_max", 0.4, 1.0, 4)),
                                  (Axis("motor.R_M", 6.0, 12.0, 2), Axis("control.kp", 5.0, 35.0, 7))])
def test_heat_map_cells_are_centred_on_the_grid_values(a, b):
    fig = heat_map_figure([a, b], _points([a, b]), "test")
    mesh = fig.axes[0].collections[0]
    corners = mesh.get_coordinates()  # (rows + 1, columns + 1, 2): x, y of each cell corner
    centres_x = (corners[0, 1:, 0] + corners[0, :-1, 0]) / 2
    centres_y = (corners[1:, 0, 1] + corners[:-1, 0, 1]) / 2
    # the grid values, computed here by hand from LO, HI and N (not read from the program)
    np.testing.assert_allclose(centres_x, [b.lower + i * (b.upper - b.lower) / (b.count - 1) for i in range(b.count)])
    np.testing.assert_allclose(centres_y, [a.lower + i * (a.upper - a.lower) / (a.count - 1) for i in range(a.count)])
    # and the axis limits leave half a cell beyond the end values
    x0, x1 = fig.axes[0].get_xlim()
    step = (b.upper - b.lower) / (b.count - 1)
    assert x0 == pytest.approx(b.lower - step / 2) and x1 == pytest.approx(b.upper + step / 2)
    # each cell's value is its own point's: row i is a's i-th value, column j is b's j-th
    colours = np.asarray(mesh.get_array()).reshape(a.count, b.count)
    for i, va in enumerate(a.values):
        for j, vb in enumerate(b.values):
            assert colours[i, j] == pytest.approx(10 + va + 100 * vb)
