"""The street graph shared by the coordinator, the agents and the predictor.

Everything a process needs to move a taxi is precomputed once and stored as
plain numpy arrays: the out-adjacency, the sector partition, sector adjacency,
and the all-pairs hop counts and next hops. One uncompressed ``.npz`` file
holds it all so that an agent process can load a city in well under a second;
``City.load(path, mmap=True)`` maps its matrices from that file instead of
reading them, so that every agent process on a host shares one copy in the
page cache.
"""

from __future__ import annotations

import json
import struct
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from city.errors import DataError

if TYPE_CHECKING:  # scipy builds cities; loading one (an agent) does not import it
    from scipy.sparse import csr_matrix

FORMAT = "surge.city/1"


@dataclass(frozen=True)
class City:
    """A directed street graph partitioned into sectors, with its shortest paths.

    Attributes
    ----------
    name : str
        Scenario name (``synthetic``, ``nyc`` …).
    xy : ndarray, shape (n, 2)
        Node coordinates; metres for the synthetic city, lon/lat for real maps (see ``crs``).
    indptr, indices : ndarray
        CSR out-adjacency; the neighbours of node ``i`` are ``indices[indptr[i]:indptr[i+1]]``.
    edge_length : ndarray
        Length in metres of each CSR edge.
    node_sector : ndarray, shape (n,)
        Sector index of every node.
    sector_names : tuple of str
        Human-readable sector names; ``sector_ids`` are external ids (e.g. TLC LocationID).
    pickup : ndarray of bool, shape (n,)
        Intersections usable for pickup and drop-off.
    sector_adj : ndarray of bool, shape (S, S)
        ``A(s)``: sectors sharing a street or a border with ``s`` (diagonal False).
    dist : ndarray of int16, shape (n, n)
        Shortest-path hop counts ``i -> j``, row-major (a row is every distance from one node).
    next_hop : ndarray, shape (n, n)
        First node after ``i`` on a shortest path ``i -> j`` (``j`` itself when ``i == j``), row-major.
    dist_m : ndarray of float32, shape (n, n)
        Length in metres of the hop-shortest path ``i -> j``.
    dist_t, next_hop_t : ndarray or None
        ``dist`` and ``next_hop`` transposed and contiguous, when mapped from a
        city file (``load(mmap=True)``); ``None`` otherwise, and the rollout
        makes them itself (:func:`agents.shortcuts.transposed`).
    """

    name: str
    crs: str
    xy: np.ndarray
    osmid: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    edge_length: np.ndarray
    node_sector: np.ndarray
    sector_names: tuple[str, ...]
    sector_ids: np.ndarray
    pickup: np.ndarray
    sector_adj: np.ndarray
    dist: np.ndarray
    next_hop: np.ndarray
    dist_m: np.ndarray
    info: dict = field(default_factory=dict)
    dist_t: np.ndarray | None = field(default=None, repr=False, compare=False)
    next_hop_t: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def n_nodes(self) -> int:
        return int(self.xy.shape[0])

    @property
    def n_edges(self) -> int:
        return int(self.indices.shape[0])

    @property
    def n_sectors(self) -> int:
        return len(self.sector_names)

    def neighbors(self, node: int) -> np.ndarray:
        return self.indices[self.indptr[node] : self.indptr[node + 1]]

    def local_sectors(self, sector: int) -> np.ndarray:
        """``A(s) ∪ {s}``, the sectors whose demand an agent in ``sector`` samples."""
        mask = self.sector_adj[sector].copy()
        mask[sector] = True
        return np.flatnonzero(mask)

    def summary(self) -> dict:
        return {"intersections": self.n_nodes, "streets": self.n_edges, "sectors": self.n_sectors}

    # ------------------------------------------------------------------ build
    @classmethod
    def build(
        cls,
        name: str,
        xy: np.ndarray,
        edges_u: np.ndarray,
        edges_v: np.ndarray,
        lengths: np.ndarray,
        node_sector: np.ndarray,
        sector_names: list[str],
        *,
        crs: str = "m",
        sector_ids: np.ndarray | None = None,
        osmid: np.ndarray | None = None,
        pickup: np.ndarray | None = None,
        border_adj: np.ndarray | None = None,
        info: dict | None = None,
    ) -> "City":
        """Build a city from an edge list of node indices ``0..n-1``.

        Parallel edges are merged (shortest length kept) and self-loops dropped.
        The graph must be strongly connected; loaders keep the largest strongly
        connected component first (see :func:`largest_scc`).
        """
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import connected_components, shortest_path

        n = int(np.asarray(xy).shape[0])
        u = np.asarray(edges_u, dtype=np.int64)
        v = np.asarray(edges_v, dtype=np.int64)
        length = np.asarray(lengths, dtype=np.float64)
        keep = u != v
        u, v, length = u[keep], v[keep], length[keep]
        order = np.lexsort((length, v, u))
        u, v, length = u[order], v[order], length[order]
        first = np.ones(u.shape[0], dtype=bool)
        first[1:] = (u[1:] != u[:-1]) | (v[1:] != v[:-1])
        u, v, length = u[first], v[first], length[first]

        adj = csr_matrix((length, (u, v)), shape=(n, n))
        adj.sort_indices()
        n_comp, _ = connected_components(adj, directed=True, connection="strong")
        if n_comp != 1:
            raise DataError(f"city {name!r}: street graph has {n_comp} strongly connected components; keep the largest first")

        # Hop-shortest paths: BFS from every target on the reversed graph gives,
        # for each node i, its successor on a shortest path i -> target.
        rev = csr_matrix((np.ones_like(length), (v, u)), shape=(n, n))
        hops, pred_rev = shortest_path(rev, method="D", unweighted=True, return_predecessors=True)
        # Row-major: the rollout's nearest-request searches read one node's row of distances.
        dist = hops.T.astype(np.int16, order="C")
        idx_dtype = np.int16 if n < np.iinfo(np.int16).max else np.int32
        next_hop = pred_rev.T.astype(idx_dtype, order="C")
        np.fill_diagonal(next_hop, np.arange(n, dtype=idx_dtype))
        dist_m = _path_lengths(adj, dist, next_hop)

        node_sector = np.asarray(node_sector, dtype=np.int32)
        n_sec = len(sector_names)
        sector_adj = np.zeros((n_sec, n_sec), dtype=bool)
        sector_adj[node_sector[u], node_sector[v]] = True
        sector_adj |= sector_adj.T
        if border_adj is not None:
            sector_adj |= np.asarray(border_adj, dtype=bool)
        np.fill_diagonal(sector_adj, False)

        return cls(
            name=name,
            crs=crs,
            xy=np.asarray(xy, dtype=np.float64),
            osmid=np.arange(n, dtype=np.int64) if osmid is None else np.asarray(osmid, dtype=np.int64),
            indptr=adj.indptr.astype(np.int32),
            indices=adj.indices.astype(np.int32),
            edge_length=adj.data.astype(np.float64),
            node_sector=node_sector,
            sector_names=tuple(sector_names),
            sector_ids=np.arange(n_sec, dtype=np.int64) if sector_ids is None else np.asarray(sector_ids, dtype=np.int64),
            pickup=np.ones(n, dtype=bool) if pickup is None else np.asarray(pickup, dtype=bool),
            sector_adj=sector_adj,
            dist=dist,
            next_hop=next_hop,
            dist_m=dist_m,
            info=dict(info or {}),
        )

    # ------------------------------------------------------------------- I/O
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        meta = {
            "format": FORMAT,
            "name": self.name,
            "crs": self.crs,
            "sector_names": list(self.sector_names),
            "info": self.info,
        }
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        arrays["dist_t"] = np.ascontiguousarray(self.dist.T) if self.dist_t is None else self.dist_t
        arrays["next_hop_t"] = np.ascontiguousarray(self.next_hop.T) if self.next_hop_t is None else self.next_hop_t
        with open(path, "wb") as fh:
            np.savez(fh, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path, mmap: bool = False) -> "City":
        """Read a city file; with ``mmap`` its arrays are copy-on-write maps of the file (and the transposed matrices come too).

        Copy-on-write rather than read-only: the pages are the page cache's,
        shared by every process that maps the file, and nothing writes to
        them; a read-only array would be a different type to numba, which
        would compile the rollout's kernels a second time.
        """
        path = Path(path)
        try:
            if mmap:
                mapped = _mapped_npz(path)
                meta = json.loads(mapped["meta"].tobytes().decode())
                arrays = {k: mapped[k] for k in _ARRAYS}
                arrays.update({k: mapped[k] for k in ("dist_t", "next_hop_t") if k in mapped})
            else:
                with np.load(path, allow_pickle=False) as z:
                    meta = json.loads(z["meta"].tobytes().decode())
                    arrays = {k: z[k] for k in _ARRAYS}
        except (OSError, KeyError, ValueError, zipfile.BadZipFile, struct.error) as exc:
            raise DataError(f"{path}: not a surge city file ({exc})") from exc
        if meta.get("format") != FORMAT:
            raise DataError(f"{path}: city format {meta.get('format')!r}, expected {FORMAT!r}")
        return cls(
            name=meta["name"],
            crs=meta["crs"],
            sector_names=tuple(meta["sector_names"]),
            info=meta.get("info", {}),
            **arrays,
        )


_ARRAYS = (
    "xy",
    "osmid",
    "indptr",
    "indices",
    "edge_length",
    "node_sector",
    "sector_ids",
    "pickup",
    "sector_adj",
    "dist",
    "next_hop",
    "dist_m",
)


def _mapped_npz(path: Path) -> dict[str, np.ndarray]:
    """The arrays of an uncompressed ``.npz`` (``np.savez``'s) as copy-on-write maps of the file, by name.

    A member of a stored (uncompressed) zip is its ``.npy`` bytes at a known
    offset: the local header, then the ``.npy`` header, then the data.
    """
    out = {}
    with zipfile.ZipFile(path) as zf, open(path, "rb") as fh:
        for info in zf.infolist():
            if info.compress_type != zipfile.ZIP_STORED:
                raise ValueError(f"member {info.filename} is compressed; it cannot be mapped")
            fh.seek(info.header_offset)
            local = fh.read(30)
            if local[:4] != b"PK\x03\x04":
                raise ValueError(f"member {info.filename} has no local header")
            name_len, extra_len = struct.unpack("<HH", local[26:30])
            fh.seek(info.header_offset + 30 + name_len + extra_len)
            version = np.lib.format.read_magic(fh)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = read_header(fh)
            if dtype.hasobject:
                raise ValueError(f"member {info.filename} holds Python objects")
            name = info.filename.removesuffix(".npy")
            if int(np.prod(shape)) == 0:
                out[name] = np.empty(shape, dtype=dtype)
                continue
            mm = np.memmap(path, dtype=dtype, mode="c", shape=shape, order="F" if fortran else "C", offset=fh.tell())
            out[name] = np.asarray(mm)
    return out


def _path_lengths(adj: csr_matrix, dist: np.ndarray, next_hop: np.ndarray) -> np.ndarray:
    """Metres along the hop-shortest paths, filled in order of increasing hop count."""
    n = dist.shape[0]
    edge = np.zeros((n, n), dtype=np.float32)
    edge[np.repeat(np.arange(n), np.diff(adj.indptr)), adj.indices] = adj.data
    flat_dist = dist.ravel()
    order = np.argsort(flat_dist, kind="stable")
    bounds = np.searchsorted(flat_dist[order], np.arange(int(flat_dist.max()) + 2))
    lengths = np.zeros(n * n, dtype=np.float32)
    nh = next_hop.ravel()
    for h in range(1, len(bounds) - 1):
        pairs = order[bounds[h] : bounds[h + 1]]
        i, j = np.divmod(pairs, n)
        hop = nh[pairs].astype(np.int64)
        lengths[pairs] = edge[i, hop] + lengths[hop * n + j]
    return lengths.reshape(n, n)


def largest_scc(n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Boolean mask of the nodes in the largest strongly connected component."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    adj = csr_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
    _, labels = connected_components(adj, directed=True, connection="strong")
    counts = np.bincount(labels)
    return labels == int(np.argmax(counts))
