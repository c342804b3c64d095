"""Is a mesh a solid: every undirected edge shared by exactly two triangles, after welding seam copies."""
from __future__ import annotations

import numpy as np

from renderer.scene.mesh_facts import is_closed

TET = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)


def test_a_tetrahedron_is_closed_and_its_variants_are_not():
    assert is_closed(TET, P) and is_closed(TET)
    assert not is_closed(TET[:3], P)  # a face missing: three edges are shared once
    assert not is_closed(np.vstack([TET, TET]), P)  # every edge four times
    assert not is_closed(np.vstack([TET, TET[:1]]), P)  # three edges three times
    assert not is_closed(np.zeros((0, 3), int), P)
    flipped = TET.copy()
    flipped[0] = flipped[0, ::-1]
    assert is_closed(flipped, P)  # orientation does not matter, only the sharing


def test_seam_copies_are_welded_but_distinct_points_are_not():
    seam = np.vstack([P, P[:1] + 1e-9])  # vertex 4: a copy of vertex 0 (a UV seam)
    tet = TET.copy()
    tet[3] = [2, 3, 4]
    assert is_closed(tet, seam) and not is_closed(tet)  # welded by position only
    apart = np.vstack([P, P[:1] + 0.01])  # 1 % of the extent away: a different point
    assert not is_closed(tet, apart)


def test_a_large_closed_mesh_far_from_the_origin():
    # a closed grid torus: (n x n) quads, wrapped in both directions, its points shifted far away
    n = 300
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = lambda a, b: (a % n) * n + (b % n)  # noqa: E731
    quads = np.stack([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)], -1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    u, w = 2 * np.pi * i.ravel() / n, 2 * np.pi * j.ravel() / n
    pts = np.stack([(2 + np.cos(w)) * np.cos(u), (2 + np.cos(w)) * np.sin(u), np.sin(w)], -1) + 1e6
    assert is_closed(tris, pts)
    assert not is_closed(tris[1:], pts)


def test_the_edge_parity_hash_is_zero_exactly_when_every_edge_occurs_an_even_number_of_times():
    from renderer.scene.mesh_facts import _odd_edge_hash

    rng = np.random.default_rng(7)
    keys = rng.integers(0, 2**51, 20_000)
    tris = rng.integers(0, len(keys), (30_000, 3))
    even = rng.permutation(np.concatenate([tris, tris, tris[:100, ::-1], tris[:100]]))
    assert _odd_edge_hash(keys, even) == 0
    for extra in (tris[:1], tris[:3], tris[5:6, [1, 0, 2]]):  # edges once or three times: caught
        assert _odd_edge_hash(keys, np.concatenate([even, extra])) != 0


def test_the_edge_parity_hash_welds_by_key_and_ignores_edge_direction():
    from renderer.scene.mesh_facts import _odd_edge_hash

    keys = np.arange(4)
    assert _odd_edge_hash(keys, TET) == 0 and _odd_edge_hash(keys, TET[:, ::-1]) == 0
    assert _odd_edge_hash(keys, TET[:3]) != 0
    seam = np.array([0, 1, 2, 3, 0])  # vertex 4 carries vertex 0's key: welded
    tet = TET.copy()
    tet[3] = [2, 3, 4]
    assert _odd_edge_hash(seam, tet) == 0 and _odd_edge_hash(np.arange(5), tet) != 0
