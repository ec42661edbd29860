"""Marching-squares segment table, with the numbering it uses.

A cell ``(i, j)`` of a field ``f (H, W)`` (``indexing="ij"``: axis 0 is x) has
corners and edges numbered::

         ul=f[i, j]  --- edge 0 (top) ---  ur=f[i, j+1]
              |                                  |
         edge 3 (left)                    edge 1 (right)
              |                                  |
        ll=f[i+1, j] -- edge 2 (bottom) -- lr=f[i+1, j+1]

Case bits: ``1 * (ul >= iso) + 2 * (ur >= iso) + 4 * (ll >= iso) + 8 * (lr >= iso)``
(a sample equal to ``iso`` is high, the tie rule of marching cubes).
Each case lists up to two directed segments ``(from_edge, to_edge)``, ``-1``
padded, oriented so the region above ``iso`` lies on one fixed side, which is
what makes every crossing vertex have one incoming and one outgoing segment.
The orientation and the saddle choices (cases 6 and 9) reproduce
``skimage.measure.find_contours`` (``positive_orientation="low"``) for both
``fully_connected`` settings; they were read off by running it on 2x2 arrays,
one per case (see ``tests/curves/test_marching_squares.py``).

The table is generated from the single-segment rule: the lone corner case
``c`` (one corner above) and its complement ``15 - c`` are the same segment in
opposite directions, and two-corner edge cases join the two outer edges.
"""

from __future__ import annotations

TOP, RIGHT, BOTTOM, LEFT = 0, 1, 2, 3

# One corner above iso: the segment cutting that corner off (from, to).
_CORNER = {1: (TOP, LEFT), 2: (RIGHT, TOP), 4: (LEFT, BOTTOM), 8: (BOTTOM, RIGHT)}
# Two adjacent corners above iso: a segment across the cell.
_SIDE = {3: (RIGHT, LEFT), 5: (TOP, BOTTOM), 10: (BOTTOM, TOP), 12: (LEFT, RIGHT)}
# Saddles: the segments for each connectivity choice.
_SADDLE_LOW = {6: ((RIGHT, TOP), (LEFT, BOTTOM)), 9: ((TOP, LEFT), (BOTTOM, RIGHT))}
_SADDLE_HIGH = {6: ((LEFT, TOP), (RIGHT, BOTTOM)), 9: ((TOP, RIGHT), (BOTTOM, LEFT))}


def _build(saddles: dict) -> list[list[tuple[int, int]]]:
    table: list[list[tuple[int, int]]] = [[(-1, -1), (-1, -1)] for _ in range(16)]
    for case, (a, b) in {**_CORNER, **_SIDE}.items():
        table[case][0] = (a, b)
        if case in _CORNER:  # complement: three corners above, same segment reversed
            table[15 - case][0] = (b, a)
    for case, (first, second) in saddles.items():
        table[case] = [first, second]
    return table


#: ``SEGMENTS[fully_connected][case] = [(from, to), (from, to)]``, ``-1`` padded.
SEGMENTS = {"low": _build(_SADDLE_LOW), "high": _build(_SADDLE_HIGH)}
