"""Where demand lives on a map: anchor sectors, busyness, points of interest, sector intensity and the gravity OD."""

from __future__ import annotations

import numpy as np

from city.graph import City
from city.io.occupancy import LOCALE_TYPES
from city.io.poi import Pois
from city.io.poi import locale_counts as poi_counts

#: Target mean trip length of the gravity OD matrix, in hops.
TARGET_TRIP_HOPS = 15.0
#: Locale counts added to every intersection so that each can be drawn at any hour.
LOCALE_FLOOR = 0.05


#: Name fragments that identify anchor sectors on a real map (TLC zone names).
ANCHOR_NAMES: dict[str, tuple[str, ...]] = {
    "theater": ("theatre", "theater", "times sq"),
    "arena": ("penn", "madison sq", "arena"),
    "expo": ("javits", "hudson yards", "clinton west", "convention"),
    "park": ("park", "stadium", "battery"),
}


def find_anchors(city: City) -> dict[str, int]:
    """Sectors of the theatre district, arena, convention centre and festival park.

    ``city.info["anchors"]`` wins (``stadium`` is accepted for ``park``).
    Otherwise each anchor is the first sector whose name contains one of
    :data:`ANCHOR_NAMES`, tried in order (on the TLC zones: Times
    Sq/Theatre District, Penn Station/Madison Sq West, West Chelsea/Hudson
    Yards, Battery Park); anchors still missing take the
    largest remaining sectors by number of pickup intersections, so every map
    gets four distinct anchors deterministically.
    """
    given = dict(city.info.get("anchors", {}))
    size = np.bincount(city.node_sector[city.pickup], minlength=city.n_sectors)
    if "park" not in given and "stadium" in given:
        given["park"] = given["stadium"]
    anchors: dict[str, int] = {}
    taken: set[int] = set()
    names = [n.lower() for n in city.sector_names]
    for key, frags in ANCHOR_NAMES.items():
        if key in given:
            anchors[key] = int(given[key])
        else:
            hit = next((s for f in frags for s, n in enumerate(names) if s not in taken and size[s] > 0 and f in n), None)
            if hit is None:
                continue
            anchors[key] = hit
        taken.add(anchors[key])
    spare = [int(s) for s in np.argsort(-size, kind="stable") if int(s) not in taken]
    for key in ANCHOR_NAMES:
        if key not in anchors:
            anchors[key] = spare.pop(0) if spare else 0
    return anchors


def _metres(city: City) -> np.ndarray:
    """Node coordinates in metres (an equirectangular projection on lon/lat maps)."""
    if city.crs == "lonlat":
        lat0 = np.deg2rad(city.xy[:, 1].mean())
        return np.column_stack([city.xy[:, 0] * 111_320.0 * np.cos(lat0), city.xy[:, 1] * 110_540.0])
    return city.xy


def _centroids(city: City) -> np.ndarray:
    xy = _metres(city)
    S = city.n_sectors
    n = np.maximum(np.bincount(city.node_sector, minlength=S), 1)
    return np.column_stack([np.bincount(city.node_sector, weights=xy[:, k], minlength=S) / n for k in range(2)])


def busyness(city: City, anchors: dict[str, int], rng: np.random.Generator) -> np.ndarray:
    """Relative activity per sector: highest around midtown (the anchors), plus seeded variety."""
    cent = _centroids(city)
    core = cent[[anchors["theater"], anchors["arena"], anchors["expo"]]].mean(axis=0)
    d = np.linalg.norm(cent - core, axis=1)
    busy = np.exp(rng.normal(0.0, 0.25, city.n_sectors)) * (0.45 + np.exp(-((d / 3000.0) ** 2)))
    busy[city.local_sectors(anchors["theater"])] *= 1.15
    for key, boost in (("theater", 1.3), ("arena", 1.3), ("expo", 1.2)):
        busy[anchors[key]] *= boost
    return busy


def locale_counts(
    city: City,
    pois: Pois | None,
    busy: np.ndarray,
    anchors: dict[str, int],
    rng: np.random.Generator,
    notes: list[str],
) -> tuple[np.ndarray, Pois]:
    """n_λ(j) from the given points of interest, or from synthetic ones placed by ``busy``."""
    if pois is None:
        pois = synthetic_pois(city, busy, anchors, rng)
        notes.append(f"points of interest: {len(pois.kind)} synthetic")
    counts = poi_counts(city.xy, city.crs, pois)
    n_kind = {k: int(np.sum(pois.kind == k)) for k in LOCALE_TYPES}
    if n_kind["restaurant"] < 0.5 * n_kind["retail"]:
        # The NYC Planning POI file lists almost no restaurants (40 in Manhattan); restaurants follow
        # shops in Manhattan, so their counts are synthesised from the retail density.
        counts[:, LOCALE_TYPES.index("restaurant")] += counts[:, LOCALE_TYPES.index("retail")]
        notes.append(f"restaurants: only {n_kind['restaurant']} in the points of interest; counts synthesised from retail density")
    return counts + LOCALE_FLOOR, pois


def synthetic_pois(city: City, busy: np.ndarray, anchors: dict[str, int], rng: np.random.Generator) -> Pois:
    """Shops, restaurants, hotels and hospitals, denser in busy sectors; hotels cluster by the theatres."""
    S = city.n_sectors
    size = np.bincount(city.node_sector[city.pickup], minlength=S).astype(np.float64)
    near_theater = np.zeros(S)
    near_theater[city.local_sectors(anchors["theater"])] = 1.0
    plan = {
        "retail": (3000, size * busy),
        "restaurant": (3500, size * busy**1.3),
        "hotel": (250, size * busy**2 * (1.0 + 3.0 * near_theater)),
        "hospital": (10, size),
    }
    jitter = 40.0 if city.crs != "lonlat" else 0.0004
    xs, ys, kinds = [], [], []
    for kind, (total, weight) in plan.items():
        sectors = rng.choice(S, size=total, p=weight / weight.sum())
        nodes = random_nodes(city, sectors, rng)
        xs.append(city.xy[nodes, 0] + rng.normal(0, jitter, total))
        ys.append(city.xy[nodes, 1] + rng.normal(0, jitter, total))
        kinds.append(np.full(total, kind))
    kind = np.concatenate(kinds)
    return Pois(np.concatenate(xs), np.concatenate(ys), kind, np.array([f"{k} {i}" for i, k in enumerate(kind)]))


def random_nodes(city: City, sectors: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A uniformly random pickup-eligible intersection in each of ``sectors``."""
    order = np.flatnonzero(city.pickup)[np.argsort(city.node_sector[city.pickup], kind="stable")]
    bounds = np.searchsorted(city.node_sector[order], np.arange(city.n_sectors + 1))
    lo, hi = bounds[sectors], bounds[np.asarray(sectors) + 1]
    return order[lo + (rng.random(len(sectors)) * (hi - lo)).astype(np.int64)]


def intensity_and_tilt(city: City, busy: np.ndarray, counts: np.ndarray, anchors: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """Each sector's share of base demand, and its evening tilt.

    The tilt leans sectors rich in restaurants and hotels (and the theatre
    district) toward the evening and the others toward the morning; it is
    centred so that the citywide total keeps the base profile.
    """
    S = city.n_sectors
    size = np.bincount(city.node_sector[city.pickup], minlength=S).astype(np.float64)
    weight = busy * size**0.7
    intensity = weight / weight.sum()
    by_kind = np.stack([np.bincount(city.node_sector, weights=counts[:, k], minlength=S) for k in range(len(LOCALE_TYPES))], axis=1)
    evening = by_kind[:, [1, 2]].sum(axis=1) / np.maximum(by_kind.sum(axis=1), 1e-9)
    z = (evening - evening.mean()) / max(evening.std(), 1e-9)
    tilt = np.clip(0.12 * z, -0.25, 0.25)
    tilt[anchors["theater"]] += 0.15
    tilt -= np.dot(intensity, tilt)
    return intensity, tilt



def gravity_od(city: City, intensity: np.ndarray) -> np.ndarray:
    """β: drop-off sector ∝ intensity × exp(−hops / L), with L set for a mean trip of :data:`TARGET_TRIP_HOPS`.

    Hops are the mean shortest-path hop counts between the pickup
    intersections of two sectors; rows sum to one.
    """
    S = city.n_sectors
    nodes = np.flatnonzero(city.pickup)
    onehot = np.zeros((len(nodes), S))
    onehot[np.arange(len(nodes)), city.node_sector[nodes]] = 1.0
    size = np.maximum(onehot.sum(axis=0), 1.0)
    hops = onehot.T @ city.dist[np.ix_(nodes, nodes)].astype(np.float64) @ onehot / np.outer(size, size)

    def beta(length: float) -> np.ndarray:
        w = intensity[None, :] * np.exp(-hops / length)
        return w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)

    lo, hi = 1.0, 500.0
    for _ in range(40):  # mean trip length grows with L: bisect on a log scale
        mid = np.sqrt(lo * hi)
        mean = float(intensity @ (beta(mid) * hops).sum(axis=1))
        lo, hi = (mid, hi) if mean < TARGET_TRIP_HOPS else (lo, mid)
    return beta(np.sqrt(lo * hi))
