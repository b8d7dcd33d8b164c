"""Triangle meshes for walls, built in metres: cylinders, drums, hoppers and boxes.

Each builder returns a :class:`Surface`: its ``(M, 3, 3)`` triangles, bounds, area, whether it
is closed (watertight and consistently oriented, normals outward) and, when closed, its volume
and which points lie inside. A surface is a mesh wall as it is::

    drum = geometry.drum(radius=0.05, length=0.02, axis="y")
    DEM(..., mesh={"drum": {"triangles": drum, "material": params.glassBeads}})

or written as STL (:meth:`Surface.write`). Its inside is an insertion region:
``insert(..., region=("mesh", drum))`` places whole particles inside it, clear of its triangles.

Curved faces are made of ``segments`` flat facets whose corners lie on the radius, so a facet's
middle lies ``radius * (1 - cos(pi / segments))`` inside it (0.2 % of the radius with the
default 48 segments).
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.errors import ConfigError
from pygran_core.formats.stl import STLTrajectory

#: Facets around a curved face by default.
SEGMENTS = 48
AXES = ("x", "y", "z")


class Surface:
    """A triangle mesh in metres: ``triangles`` ``(M, 3, 3)`` (corner coordinates), each
    triangle's corners counter-clockwise seen from outside on closed surfaces.

    ``inscribed`` is a primitive region (``('cylinder', ...)``, ``('block', ...)``) lying inside
    the mesh, given by the builders: engines whose solver inserts particles itself (LIGGGHTS)
    insert into it when asked to insert inside the mesh.
    """

    def __init__(
        self, triangles: np.ndarray, name: str = "surface", inscribed: tuple[object, ...] | None = None
    ) -> None:
        data = np.array(triangles, dtype=float)
        if data.ndim != 3 or data.shape[1:] != (3, 3) or len(data) == 0:
            raise ConfigError(
                "triangles must be an (M, 3, 3) array of corner coordinates with M >= 1, "
                f"got shape {data.shape}"
            )
        if not np.isfinite(data).all():
            raise ConfigError(f"surface {name!r}: a triangle corner is not finite")
        data.setflags(write=False)
        self.triangles = data
        self.name = name
        self.inscribed = inscribed
        self._edges: tuple[int, int] | None = None

    @classmethod
    def read(cls, path: str | os.PathLike[str], scale: float = 1.0) -> Surface:
        """The triangles of an STL file, coordinates times ``scale`` (1e-3 for a file in mm)."""
        frame = STLTrajectory([Path(path)], scale=scale).read_frame(0)
        points, cells = frame.arrays["points"], frame.arrays["cells"]
        return cls(points[cells[:, :3]], name=Path(path).stem)

    def __len__(self) -> int:
        return len(self.triangles)

    def __repr__(self) -> str:
        return f"Surface({self.name!r}, {len(self)} triangles, sha1 {self.digest[:12]})"

    @property
    def digest(self) -> str:
        """SHA-1 of the triangles: the same for the same mesh."""
        return hashlib.sha1(np.ascontiguousarray(self.triangles).tobytes()).hexdigest()

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box ``(3, 2)``: (lo, hi) of x, y and z in metres."""
        points = self.triangles.reshape(-1, 3)
        return np.column_stack([points.min(axis=0), points.max(axis=0)])

    @property
    def area(self) -> float:
        """Total area in m^2."""
        return float(np.linalg.norm(self._normals(), axis=1).sum() / 2)

    def _normals(self) -> np.ndarray:
        t = self.triangles
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    def _edge_counts(self) -> tuple[int, int]:
        """(edges not shared by exactly two triangles, shared edges both triangles run the same
        way), corners closer than 1e-9 of the mesh's size welded."""
        if self._edges is None:
            size = float(np.ptp(self.triangles.reshape(-1, 3), axis=0).max()) or 1.0
            keys = np.round(self.triangles.reshape(-1, 3) / (1e-9 * size)).astype(np.int64)
            _, vertex = np.unique(keys, axis=0, return_inverse=True)
            corners = vertex.reshape(-1, 3)
            directed = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])
            undirected = np.sort(directed, axis=1)
            _, uses = np.unique(undirected, axis=0, return_counts=True)
            _, same_way = np.unique(directed, axis=0, return_counts=True)
            self._edges = (int(np.count_nonzero(uses != 2)), int(np.count_nonzero(same_way > 1)))
        return self._edges

    @property
    def open_edges(self) -> int:
        """Edges not shared by exactly two triangles (0 on a watertight surface)."""
        return self._edge_counts()[0]

    @property
    def closed(self) -> bool:
        """Watertight (every edge shared by two triangles), consistently oriented and enclosing
        a positive volume (normals outward)."""
        open_edges, flipped = self._edge_counts()
        return open_edges == 0 and flipped == 0 and self._signed_volume() > 0

    def _signed_volume(self) -> float:
        t = self.triangles
        return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)

    @property
    def volume(self) -> float:
        """Enclosed volume in m^3 (closed surfaces only)."""
        self.require_closed("its volume")
        return self._signed_volume()

    def require_closed(self, purpose: str) -> None:
        """Raise :class:`ConfigError` unless the surface is closed, saying why it is not."""
        if self.closed:
            return
        open_edges, flipped = self._edge_counts()
        if open_edges:
            why = f"{open_edges} of its edges are not shared by exactly two triangles (it has holes)"
        elif flipped:
            why = f"{flipped} of its edges are run the same way by both their triangles (mixed orientation)"
        else:
            why = "its triangles face inward (negative volume): reverse their corners' order"
        raise ConfigError(
            f"surface {self.name!r} is not closed, so it has no inside for {purpose}: {why}. Build it "
            "closed (geometry.drum, geometry.box, or caps=True), or use a primitive region"
        )

    def contains(self, points: np.ndarray, margin: float | np.ndarray = 0.0) -> np.ndarray:
        """Which ``points`` (n, 3) lie inside the closed surface, at least ``margin`` (per point)
        from every triangle: the generalised winding number (sum of the triangles' solid angles
        over 4 pi) is above one half inside."""
        self.require_closed("points inside it")
        points = np.asarray(points, float).reshape(-1, 3)
        margin = np.broadcast_to(np.asarray(margin, float), (len(points),))
        inside = np.zeros(len(points), bool)
        box = self.bounds
        near = np.all(
            (points >= box[:, 0] + margin[:, None]) & (points <= box[:, 1] - margin[:, None]), axis=1
        )
        if self.inscribed is not None:  # a ball inside the inscribed primitive is inside the mesh
            inside = near & _inside_primitive(self.inscribed, points, margin)
            near &= ~inside
        chosen = np.flatnonzero(near)
        if len(chosen):
            inside[chosen] = winding_number(points[chosen], self.triangles) > 0.5
        chosen = np.flatnonzero(inside & near & (margin > 0))
        if len(chosen):
            inside[chosen] = triangle_distance(points[chosen], self.triangles) >= margin[chosen]
        return inside

    def __add__(self, other: Surface) -> Surface:
        """Both surfaces' triangles as one mesh (a hopper and its lid)."""
        return Surface(np.concatenate([self.triangles, other.triangles]), f"{self.name}+{other.name}")

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Write the surface as an ASCII STL file (metres); returns its path."""
        target = Path(path)
        normals = self._normals()
        lengths = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
        facet = "facet normal %r %r %r\n outer loop\n" + "  vertex %r %r %r\n" * 3 + " endloop\nendfacet\n"
        rows = np.column_stack([normals, self.triangles.reshape(-1, 9)]).tolist()
        body = "".join(facet % tuple(row) for row in rows)
        target.write_text(f"solid {self.name}\n{body}endsolid {self.name}\n")
        return target


def _inside_primitive(region: tuple[object, ...], points: np.ndarray, margin: np.ndarray) -> np.ndarray:
    """Which ``points`` lie ``margin`` inside a builder's inscribed block or cylinder."""
    if region[0] == "block":
        box = np.array(region[1:], float).reshape(3, 2)
        return np.all(
            (points >= box[:, 0] + margin[:, None]) & (points <= box[:, 1] - margin[:, None]), axis=1
        )
    axis = str(region[1])
    c1, c2, radius, lo, hi = (float(v) for v in region[2:])  # type: ignore[arg-type]
    across = [i for i in range(3) if AXES[i] != axis]
    along = points[:, AXES.index(axis)]
    r = np.hypot(points[:, across[0]] - c1, points[:, across[1]] - c2)
    return (r <= radius - margin) & (along >= lo + margin) & (along <= hi - margin)


def winding_number(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The generalised winding number of each point (P, 3) about the triangles (T, 3, 3):
    1 inside a closed, outward-oriented surface, 0 outside (Van Oosterom and Strackee's solid
    angle of each triangle, summed over 4 pi)."""
    result = np.empty(len(points))
    batch = max(1, 2_000_000 // (3 * len(triangles)))  # about 50 MB of temporaries
    corners = triangles.transpose(1, 2, 0)  # (3 corners, 3 axes, T)
    for start in range(0, len(points), batch):
        p = points[start : start + batch, :, None]  # (P, 3, 1)
        a, b, c = corners[0] - p, corners[1] - p, corners[2] - p  # (P, 3, T)
        la, lb, lc = (np.sqrt((v * v).sum(axis=1)) for v in (a, b, c))
        cross = np.cross(b, c, axis=1)
        numerator = (a * cross).sum(axis=1)
        denominator = (
            la * lb * lc + (a * b).sum(axis=1) * lc + (a * c).sum(axis=1) * lb + (b * c).sum(axis=1) * la
        )
        result[start : start + batch] = np.arctan2(numerator, denominator).sum(axis=1) / (2 * math.pi)
    return result


def triangle_distance(points: np.ndarray, triangles: np.ndarray, batch: int = 256) -> np.ndarray:
    """Distance from each point (P, 3) to the nearest of the triangles (T, 3, 3)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    best = np.full(len(points), np.inf)
    for start in range(0, len(points), batch):
        p = points[start : start + batch, None, :]
        ap = p - a
        d1, d2 = np.einsum("ptk,tk->pt", ap, ab), np.einsum("ptk,tk->pt", ap, ac)
        bp, cp = p - b, p - c
        d3, d4 = np.einsum("ptk,tk->pt", bp, ab), np.einsum("ptk,tk->pt", bp, ac)
        d5, d6 = np.einsum("ptk,tk->pt", cp, ab), np.einsum("ptk,tk->pt", cp, ac)
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        with np.errstate(divide="ignore", invalid="ignore"):
            denom = va + vb + vc
            v, w = vb / denom, vc / denom  # interior barycentric coordinates
            s_ab = np.clip(d1 / (d1 - d3), 0, 1)
            s_ac = np.clip(d2 / (d2 - d6), 0, 1)
            s_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
        inside = (va >= 0) & (vb >= 0) & (vc >= 0) & (denom > 0)
        candidates = [
            np.where(inside[..., None], a + v[..., None] * ab + w[..., None] * ac, np.nan),
            a + np.nan_to_num(s_ab)[..., None] * ab,
            a + np.nan_to_num(s_ac)[..., None] * ac,
            b + np.nan_to_num(s_bc)[..., None] * (c - b),
        ]
        distances = np.stack([np.linalg.norm(p - q, axis=-1) for q in candidates])
        best[start : start + batch] = np.nanmin(distances, axis=(0, 2))
    return best


# -- builders ----------------------------------------------------------------------------------


def _frame(axis: str) -> np.ndarray:
    """Rows: the two directions across ``axis`` and ``axis`` itself (a right-handed frame)."""
    if axis not in AXES:
        raise ConfigError(f"axis must be one of {AXES}, got {axis!r}")
    along = AXES.index(axis)
    eye = np.eye(3)
    return np.stack([eye[(along + 1) % 3], eye[(along + 2) % 3], eye[along]])


def _positive(value: float, what: str, allow_zero: bool = False) -> float:
    number = float(value)
    if not math.isfinite(number) or number < 0 or (number == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ConfigError(f"{what} must be a {kind} length in metres, got {value!r}")
    return number


def _segments(value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 3:
        raise ConfigError(f"segments must be an integer of at least 3, got {value!r}")
    return value


def _band(r0: float, z0: float, r1: float, z1: float, n: int) -> list[np.ndarray]:
    """The lateral triangles between the circle of radius ``r0`` at height ``z0`` and of
    ``r1`` at ``z1 > z0`` (local frame, axis z), normals outward; a zero radius is an apex."""
    angles = np.linspace(0, 2 * math.pi, n + 1)
    ring0 = np.column_stack([r0 * np.cos(angles), r0 * np.sin(angles), np.full(n + 1, z0)])
    ring1 = np.column_stack([r1 * np.cos(angles), r1 * np.sin(angles), np.full(n + 1, z1)])
    parts = []
    if r0 > 0:
        parts.append(np.stack([ring0[:-1], ring0[1:], ring1[1:]], axis=1))
    if r1 > 0:
        parts.append(np.stack([ring0[:-1], ring1[1:], ring1[:-1]], axis=1))
    return parts


def _disc(radius: float, z: float, n: int, up: bool) -> np.ndarray:
    """A fan of ``n`` triangles closing the circle at height ``z``, normal +z when ``up``."""
    angles = np.linspace(0, 2 * math.pi, n + 1)
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(n + 1, z)])
    centre = np.tile([0.0, 0.0, z], (n, 1))
    return np.stack([centre, ring[:-1], ring[1:]] if up else [centre, ring[1:], ring[:-1]], axis=1)


def _place(local: np.ndarray, axis: str, centre: Sequence[float]) -> np.ndarray:
    return local @ _frame(axis) + np.asarray(centre, float)


def _cylinder_region(
    axis: str, centre: Sequence[float], radius: float, lo: float, hi: float, n: int
) -> tuple[object, ...]:
    """The LIGGGHTS cylinder region inscribed in the faceted cylinder (through the facets' middles)."""
    point = np.asarray(centre, float)
    c1, c2 = (float(point[i]) for i in range(3) if AXES[i] != axis)  # LIGGGHTS' order: x before z
    along = float(point[AXES.index(axis)])
    return ("cylinder", axis, c1, c2, radius * math.cos(math.pi / n), along + lo, along + hi)


def cylinder(
    radius: float,
    length: float,
    axis: str = "z",
    centre: Sequence[float] = (0.0, 0.0, 0.0),
    segments: int = SEGMENTS,
    caps: bool = False,
) -> Surface:
    """A cylinder of ``radius`` and ``length`` (m) about ``axis``, centred on ``centre``: an
    open tube, or closed by flat ``caps`` (then a drum)."""
    radius, length, n = _positive(radius, "radius"), _positive(length, "length"), _segments(segments)
    half = length / 2
    local = _band(radius, -half, radius, half, n)
    if caps:
        local += [_disc(radius, -half, n, up=False), _disc(radius, half, n, up=True)]
    inscribed = _cylinder_region(axis, centre, radius, -half, half, n) if caps else None
    return Surface(_place(np.concatenate(local), axis, centre), "drum" if caps else "cylinder", inscribed)


def drum(
    radius: float,
    length: float,
    axis: str = "y",
    centre: Sequence[float] = (0.0, 0.0, 0.0),
    segments: int = SEGMENTS,
) -> Surface:
    """A closed rotating drum: a cylinder of ``radius`` and ``length`` (m) about ``axis``
    (horizontal ``y`` by default), capped at both ends, centred on ``centre``."""
    return cylinder(radius, length, axis, centre, segments, caps=True)


def hopper(
    radius: float,
    outlet: float,
    height: float,
    axis: str = "z",
    base: Sequence[float] = (0.0, 0.0, 0.0),
    wall_height: float = 0.0,
    segments: int = SEGMENTS,
    closed: bool = False,
) -> Surface:
    """A conical hopper: a cone from the ``outlet`` radius at ``base`` (its centre) up to
    ``radius`` at ``height`` along ``axis``, and a cylindrical wall of ``wall_height`` above.
    Open at the outlet and the top; ``closed=True`` adds flat discs there (a closed frustum,
    whose inside is then a region). ``outlet=0`` makes a pointed cone."""
    radius, height = _positive(radius, "radius"), _positive(height, "height")
    outlet = _positive(outlet, "outlet radius", allow_zero=True)
    wall_height = _positive(wall_height, "wall_height", allow_zero=True)
    n = _segments(segments)
    if outlet >= radius:
        raise ConfigError(f"the hopper's outlet radius ({outlet:g} m) must be below its radius ({radius:g})")
    local = _band(outlet, 0.0, radius, height, n)
    top = height
    if wall_height:
        local += _band(radius, height, radius, height + wall_height, n)
        top = height + wall_height
    if closed:
        local.append(_disc(radius, top, n, up=True))
        if outlet:
            local.append(_disc(outlet, 0.0, n, up=False))
    return Surface(_place(np.concatenate(local), axis, base), "hopper")


def cone(
    radius_low: float,
    radius_high: float,
    height: float,
    axis: str = "z",
    base: Sequence[float] = (0.0, 0.0, 0.0),
    segments: int = SEGMENTS,
    caps: bool = False,
) -> Surface:
    """A cone (frustum) from ``radius_low`` at ``base`` to ``radius_high`` at ``height`` along
    ``axis``; open, or closed by flat ``caps``. Either radius may be 0 (an apex)."""
    low = _positive(radius_low, "radius_low", allow_zero=True)
    high = _positive(radius_high, "radius_high", allow_zero=True)
    height, n = _positive(height, "height"), _segments(segments)
    if low == high == 0:
        raise ConfigError("a cone needs a positive radius at one end at least")
    local = _band(low, 0.0, high, height, n)
    if caps:
        local += [_disc(r, z, n, up) for r, z, up in ((low, 0.0, False), (high, height, True)) if r > 0]
    return Surface(_place(np.concatenate(local), axis, base), "cone")


def box(lo: Sequence[float], hi: Sequence[float], open_top: bool = False) -> Surface:
    """An axis-aligned box from corner ``lo`` to ``hi`` (m): 12 triangles, closed, or 10
    without the face at the top of z (a container)."""
    low, high = np.asarray(lo, float), np.asarray(hi, float)
    if low.shape != (3,) or high.shape != (3,) or not np.all(high > low):
        raise ConfigError(f"box needs corners lo < hi on every axis, got lo={lo!r}, hi={hi!r}")
    corner = np.array([[(high if (k >> axis) & 1 else low)[axis] for axis in range(3)] for k in range(8)])
    # faces as corner indices (bit 0: x, 1: y, 2: z), counter-clockwise from outside
    faces = [(0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1), (4, 5, 7, 6)]
    if open_top:
        faces = faces[:-1]
    triangles = [corner[[a, b, c]] for a, b, c, d in faces] + [corner[[a, c, d]] for a, b, c, d in faces]
    inscribed = None if open_top else ("block", *np.column_stack([low, high]).reshape(-1).tolist())
    return Surface(np.array(triangles), "box", inscribed)


def as_surface(value: object, name: str) -> Surface:
    """A :class:`Surface` from a surface or an ``(M, 3, 3)`` array-like of triangle corners."""
    if isinstance(value, Surface):
        return value
    if isinstance(value, (str, bytes, os.PathLike)) or not hasattr(value, "__len__"):
        raise ConfigError(
            f"mesh {name!r}: 'triangles' takes a geometry surface or an (M, 3, 3) array of corners "
            f"in metres, got {type(value).__name__}"
        )
    try:
        return Surface(np.asarray(value, float), name)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"mesh {name!r}: 'triangles' is not an array of numbers: {exc}") from None
