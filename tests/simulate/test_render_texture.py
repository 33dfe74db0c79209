"""The renderer's board texture is the exact area average of the pattern: a square edge inside a texel is not moved
to the texel boundary (which shifted every corner of a grid line alike, up to half a texel)."""

import numpy as np
import pytest

from simulate.camera import BLACK, WHITE, BoardSpec, board_texture


@pytest.mark.parametrize("spec", [BoardSpec(1.0, 7, 6, 0.12), BoardSpec(0.9, 8, 5, 0.1013), BoardSpec(0.7, 5, 8, 0.07)])
@pytest.mark.parametrize("ppm", [333.3, 961.7, 2500.0])
def test_each_row_of_texels_holds_the_exact_dark_length(spec, ppm):
    tex, used = board_texture(spec, ppm)
    dark = (WHITE - tex) / (WHITE - BLACK)                                    # dark share per texel
    n_dark = (spec.squares_x * spec.squares_y) // 2
    np.testing.assert_allclose(dark.sum() / used ** 2, n_dark * spec.square_m ** 2, rtol=1e-5)  # float32 texels
    # a texel row inside the first row of squares: its dark length is that row's dark squares (to 0.01 mm)
    oy = spec.pattern_origin[1]
    v = int(np.ceil(oy * used)) + 1
    assert (v + 1) / used < oy + spec.square_m
    np.testing.assert_allclose(dark[v].sum() / used, (spec.squares_x // 2) * spec.square_m, atol=1e-5)


def test_the_dark_share_locates_a_square_edge_inside_its_texel():
    spec = BoardSpec(1.0, 7, 6, 0.12)
    tex, used = board_texture(spec, 961.7)
    ox, oy = spec.pattern_origin
    v = int((oy + 0.5 * spec.square_m) * used)                                # a row through the first squares
    edge = ox + spec.square_m                                                 # light -> dark along x
    u = int(edge * used)
    share = (WHITE - tex[v, u]) / (WHITE - BLACK)
    np.testing.assert_allclose(u / used + (1 - share) / used, edge, atol=1e-6)
    assert 0.0 < share < 1.0
