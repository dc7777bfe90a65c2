"""The embedded synthetic city: a seeded, Manhattan-like street grid.

Avenues run south→north (columns), streets west→east (rows).  Avenues and
streets alternate one-way directions; every twelfth street is a two-way
crosstown street; a one-way diagonal (the city's "Broadway") cuts southbound
across the grid; the lower end tapers and loses its regularity, like a
village street plan.  The graph keeps its largest strongly connected
component, and 38 sectors cover it: irregular clusters downtown, then bands of
streets split into a west and an east half.
"""

from __future__ import annotations

import numpy as np

from city.graph import City, largest_scc

N_AVENUES = 12
N_STREETS = 196
AVENUE_SPACING_M = 260.0
STREET_SPACING_M = 80.0
LOWER_ROWS = 40
LOWER_SECTORS = 8
BANDS = 15


def synthetic_city(seed: int = 0) -> City:
    """Build the synthetic city; the same seed always gives the same map."""
    rng = np.random.default_rng(seed)
    cols, rows = np.meshgrid(np.arange(N_AVENUES), np.arange(N_STREETS))
    cols, rows = cols.ravel(), rows.ravel()
    node_id = -np.ones((N_STREETS, N_AVENUES), dtype=np.int64)

    # Taper the lower end: fewer avenues reach the southern tip.
    depth = np.clip((LOWER_ROWS - rows) / LOWER_ROWS, 0.0, 1.0)
    west_cut = np.floor(depth**1.5 * 4 + rng.uniform(0, 1, rows.size) * depth * 1.5)
    east_cut = np.floor(depth**1.2 * 3 + rng.uniform(0, 1, rows.size) * depth * 1.5)
    keep = (cols >= west_cut) & (cols <= N_AVENUES - 1 - east_cut)
    cols, rows = cols[keep], rows[keep]
    node_id[rows, cols] = np.arange(cols.size)

    x = cols * AVENUE_SPACING_M
    y = rows * STREET_SPACING_M
    lower = rows < LOWER_ROWS
    # Downtown streets bend and wander.
    angle = np.where(lower, 0.35 * (LOWER_ROWS - rows) / LOWER_ROWS, 0.0)
    x = np.where(lower, x * np.cos(angle) - (y - LOWER_ROWS * STREET_SPACING_M) * np.sin(angle) * 0.3, x)
    jitter = rng.normal(0.0, 18.0, (cols.size, 2)) * lower[:, None]
    xy = np.column_stack([x, y]) + jitter

    u: list[np.ndarray] = []
    v: list[np.ndarray] = []

    def link(a: np.ndarray, b: np.ndarray) -> None:
        ok = (a >= 0) & (b >= 0)
        u.append(a[ok])
        v.append(b[ok])

    # Avenues: alternate northbound / southbound; the widest two are two-way.
    for c in range(N_AVENUES):
        col = node_id[:, c]
        a, b = col[:-1], col[1:]
        if c in (3, 8):
            link(a, b)
            link(b, a)
        elif c % 2 == 0:
            link(a, b)
        else:
            link(b, a)
    # Streets: alternate eastbound / westbound; every twelfth is two-way crosstown.
    for r in range(N_STREETS):
        row = node_id[r]
        a, b = row[:-1], row[1:]
        two_way = r % 12 == 6 or (r < LOWER_ROWS and rng.uniform() < 0.35)
        if two_way or r % 2 == 0:
            link(a, b)
        if two_way or r % 2 == 1:
            link(b, a)
    # The diagonal runs from the upper west side down to the lower east, southbound.
    diag_rows = np.arange(LOWER_ROWS - 10, N_STREETS)
    diag_cols = np.clip(2 + (N_STREETS - diag_rows) * 7 // (N_STREETS - LOWER_ROWS + 10), 0, N_AVENUES - 1)
    d_nodes = node_id[diag_rows, diag_cols]
    step = np.flatnonzero(diag_cols[1:] != diag_cols[:-1])
    link(d_nodes[step + 1], d_nodes[step])
    # Irregular downtown lanes: a few extra two-way diagonal links.
    low_nodes = np.flatnonzero(lower)
    extra = rng.choice(low_nodes, size=low_nodes.size // 6, replace=False)
    nb = node_id[np.clip(rows[extra] + 1, 0, N_STREETS - 1), np.clip(cols[extra] + rng.choice([-1, 1], extra.size), 0, N_AVENUES - 1)]
    link(extra, nb)
    link(nb, extra)

    eu, ev = np.concatenate(u), np.concatenate(v)
    # Downtown loses a few segments (construction, pedestrian plazas).
    low_edge = lower[eu] & lower[ev]
    drop = low_edge & (rng.uniform(size=eu.size) < 0.06)
    eu, ev = eu[~drop], ev[~drop]

    scc = largest_scc(cols.size, eu, ev)
    remap = -np.ones(cols.size, dtype=np.int64)
    remap[scc] = np.arange(int(scc.sum()))
    keep_e = scc[eu] & scc[ev]
    eu, ev = remap[eu[keep_e]], remap[ev[keep_e]]
    xy, cols, rows = xy[scc], cols[scc], rows[scc]
    lengths = np.linalg.norm(xy[eu] - xy[ev], axis=1)

    node_sector, names, anchors = _sectors(xy, cols, rows, rng)
    return City.build(
        "synthetic",
        xy,
        eu,
        ev,
        lengths,
        node_sector,
        names,
        crs="m",
        info={"seed": seed, "anchors": anchors, "dropped_outside_scc": int((~scc).sum())},
    )


def _sectors(xy: np.ndarray, cols: np.ndarray, rows: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, list[str], dict[str, int]]:
    """Downtown: k-means clusters; above it, street bands split west/east."""
    sector = np.zeros(len(xy), dtype=np.int32)
    lower = rows < LOWER_ROWS
    pts = xy[lower]
    centers = pts[rng.choice(len(pts), LOWER_SECTORS, replace=False)]
    for _ in range(25):
        label = np.argmin(((pts[:, None, :] - centers[None]) ** 2).sum(-1), axis=1)
        centers = np.array([pts[label == k].mean(0) if np.any(label == k) else centers[k] for k in range(LOWER_SECTORS)])
    order = np.argsort(centers[:, 1] * 10 + centers[:, 0] / 1000)
    rank = np.empty(LOWER_SECTORS, dtype=np.int32)
    rank[order] = np.arange(LOWER_SECTORS)
    sector[lower] = rank[label]
    names = [f"Downtown {k + 1}" for k in range(LOWER_SECTORS)]

    band_height = (N_STREETS - LOWER_ROWS) / BANDS
    band = np.minimum(((rows - LOWER_ROWS) / band_height).astype(int), BANDS - 1)
    east = cols >= N_AVENUES // 2
    upper = ~lower
    sector[upper] = LOWER_SECTORS + 2 * band[upper] + east[upper]
    for b in range(BANDS):
        names += [f"Band {b + 1} West", f"Band {b + 1} East"]
    anchors = {
        "arena": LOWER_SECTORS + 2 * 4,
        "expo": LOWER_SECTORS + 2 * 5,
        "theater": LOWER_SECTORS + 2 * 7,
        "park": LOWER_SECTORS + 2 * 13 + 1,
    }
    names[anchors["arena"]] = "Arena District West"
    names[anchors["expo"]] = "Convention Center West"
    names[anchors["theater"]] = "Theater District West"
    names[anchors["park"]] = "Park Side East"
    return sector, names, anchors
