"""Where a scene puts its nodes: a graded grid, fine over the working region under the electrodes.

The ``resolution`` section of a scene (issue #21) replaces the uniform ``grid`` by a graded
tensor-product grid (``Grid.graded``): cells of at most ``fine_m`` over a working box
(``fine_z_m`` in z where given), growing by ``growth`` per cell (capped at ``max_cell_m``) to the
block's faces. The working box is given, or by default the electrodes' contacts (a path's
bounding box for a moving electrode) plus ``margin_m`` sideways and ``depth_m`` down from the
top surface. ``surface_m`` (optional) shrinks the box's cells toward its top side to that height,
by the same growth ratio. ``deep_m`` (optional) adds a deep tier below the box: down to that depth
the cells keep the box's width and grow in height only to ``deep_z_m``, so a crater that digs
below the box stays in resolved cells at a fraction of the box's cost per depth.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from diathermy.errors import MeshError
from diathermy.mesh import Grid

MAX_GRADED_NODES = 4_000_000
"""Most nodes a graded scene may ask for (~60 GiB of engine memory at 16 kB per node)."""

Point3 = tuple[
    Annotated[float, Field(allow_inf_nan=False)],
    Annotated[float, Field(allow_inf_nan=False)],
    Annotated[float, Field(allow_inf_nan=False)],
]


class Resolution(BaseModel):
    """A graded grid: fine cells over the working region, coarse in the far field. Lengths in m."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    fine_m: Annotated[float, Field(ge=2e-5, le=0.05, allow_inf_nan=False)] = Field(
        0.4e-3, description="largest cell over the working region, m"
    )
    fine_z_m: Annotated[float, Field(ge=2e-5, le=0.05, allow_inf_nan=False)] | None = Field(
        None,
        description="largest cell height (z) over the working region, m; None: fine_m. The "
        "crater's depth and the first cut follow the cell height, its volume the cells' width "
        "(fine_m; docs/resolution.md)",
    )
    growth: Annotated[float, Field(ge=1.0, le=2.0, allow_inf_nan=False)] = Field(
        1.25, description="largest ratio of neighbouring cells away from the working region"
    )
    max_cell_m: Annotated[float, Field(gt=0, le=0.05, allow_inf_nan=False)] = Field(
        6.25e-3, description="largest cell anywhere, m"
    )
    surface_m: Annotated[float, Field(ge=2e-5, le=0.05, allow_inf_nan=False)] | None = Field(
        None,
        description="cell height at the top surface over the working region, m: the cells "
        "shrink from fine_m to it by at most growth per cell, so the thin layer under the "
        "contact that boils first is resolved; None: fine_m up to the surface",
    )
    margin_m: Annotated[float, Field(ge=0, le=0.1, allow_inf_nan=False)] = Field(
        2e-3, description="default working region: sideways margin beyond the contacts, m"
    )
    depth_m: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)] = Field(
        12e-3, description="default working region: depth below the top surface, m"
    )
    deep_m: Annotated[float, Field(gt=0, le=1.0, allow_inf_nan=False)] | None = Field(
        None,
        description="deep tier: depth below the top surface, m, down to which the cells under "
        "the working region grow in height only to deep_z_m (their width stays fine_m), for a "
        "crater that digs below depth_m; None: no tier",
    )
    deep_z_m: Annotated[float, Field(ge=2e-5, le=0.05, allow_inf_nan=False)] | None = Field(
        None,
        description="largest cell height in the deep tier, m; None: twice the region's (at "
        "most max_cell_m)",
    )
    region_m: tuple[Point3, Point3] | None = Field(
        None,
        description="working box ((x, y, z) low corner, (x, y, z) high corner) in m; None: "
        "the electrodes' contacts (a path's bounding box) plus margin_m, depth_m from the top",
    )

    @model_validator(mode="after")
    def _consistent(self) -> Resolution:
        for name, fine in (("fine_m", self.fine_m), ("fine_z_m", self.fine_z_m)):
            if fine is not None and self.max_cell_m < fine:
                raise ValueError(
                    f"max_cell_m ({self.max_cell_m} m) must be at least {name} ({fine} m)"
                )
        height = "fine_z_m" if self.fine_z_m is not None else "fine_m"
        if self.surface_m is not None and self.surface_m > self.fine_spacing_m[2]:
            raise ValueError(
                f"surface_m ({self.surface_m} m) must not exceed {height} "
                f"({self.fine_spacing_m[2]} m)"
            )
        if self.deep_m is not None:
            if self.region_m is None and self.deep_m <= self.depth_m:
                raise ValueError(
                    f"deep_m ({self.deep_m} m) must exceed depth_m ({self.depth_m} m): the deep "
                    "tier lies below the working region"
                )
            if not self.fine_spacing_m[2] <= self.deep_cell_m <= self.max_cell_m:
                raise ValueError(
                    f"deep_z_m ({self.deep_cell_m} m) must lie between {height} "
                    f"({self.fine_spacing_m[2]} m) and max_cell_m ({self.max_cell_m} m)"
                )
        if self.region_m is not None:
            lo, hi = self.region_m
            if any(b < a for a, b in zip(lo, hi, strict=True)):
                raise ValueError(f"region_m: high corner {hi} must not lie below the low {lo}")
        return self

    @property
    def fine_spacing_m(self) -> tuple[float, float, float]:
        """The working region's largest cell along (x, y, z) in m."""
        z = self.fine_m if self.fine_z_m is None else self.fine_z_m
        return (self.fine_m, self.fine_m, z)

    @property
    def deep_cell_m(self) -> float:
        """The deep tier's largest cell height in m (``deep_z_m``, or twice the region's within
        ``max_cell_m``)."""
        if self.deep_z_m is None:
            return min(2.0 * self.fine_spacing_m[2], self.max_cell_m)
        return self.deep_z_m


class _Path(Protocol):
    @property
    def waypoints_m(self) -> Sequence[tuple[float, float]]: ...
    @property
    def kind(self) -> str: ...


class _Electrode(Protocol):
    @property
    def position_m(self) -> tuple[float, float]: ...
    @property
    def radius_m(self) -> float: ...
    @property
    def path(self) -> _Path | None: ...


def contact_footprint(electrode: _Electrode) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) low and high corners in m of every point the electrode's contact disk can cover.

    A spline path (uniform Catmull-Rom) stays within the hull of its Bezier control points,
    P_i + (P_i+1 - P_i-1) / 6, so the waypoints' box grows by the largest such offset.
    """
    pts = np.array([electrode.position_m], dtype=float)
    pad = float(electrode.radius_m)
    if electrode.path is not None:
        wp = np.asarray(electrode.path.waypoints_m, dtype=float)
        pts = np.vstack([pts, wp])
        if electrode.path.kind == "spline":
            ext = np.vstack([wp[:1], wp, wp[-1:]])
            pad += float(np.linalg.norm(ext[2:] - ext[:-2], axis=1).max()) / 6.0
    return pts.min(axis=0) - pad, pts.max(axis=0) + pad


Box = tuple[tuple[float, float, float], tuple[float, float, float]]
"""An axis-aligned box ((x, y, z) low, (x, y, z) high) in m."""


def working_region(
    resolution: Resolution,
    block_m: Sequence[float],
    electrodes: Sequence[_Electrode],
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
) -> Box:
    """The working box ((x, y, z) low, (x, y, z) high) in m, clipped to the block."""
    o, size = np.asarray(origin_m, dtype=float), np.asarray(block_m, dtype=float)
    if resolution.region_m is not None:
        lo, hi = (np.asarray(c, dtype=float) for c in resolution.region_m)
    else:
        top = o[2] + size[2]
        if electrodes:
            corners = [contact_footprint(e) for e in electrodes]
            lo_xy = np.min([c[0] for c in corners], axis=0) - resolution.margin_m
            hi_xy = np.max([c[1] for c in corners], axis=0) + resolution.margin_m
        else:  # no electrode: the centre of the top face
            lo_xy = hi_xy = o[:2] + 0.5 * size[:2]
        lo = np.array([lo_xy[0], lo_xy[1], top - resolution.depth_m])
        hi = np.array([hi_xy[0], hi_xy[1], top])
    lo, hi = np.clip(lo, o, o + size), np.clip(hi, o, o + size)
    return (
        (float(lo[0]), float(lo[1]), float(lo[2])),
        (float(hi[0]), float(hi[1]), float(hi[2])),
    )


def deep_tier(resolution: Resolution, box: Box, top_m: float) -> tuple[float, float] | None:
    """The deep tier below the working ``box`` as (length, largest cell height) in m, clipped to
    the block's bottom at z = 0; None without one. Raises MeshError when ``deep_m`` does not
    reach below the box."""
    if resolution.deep_m is None:
        return None
    bottom = max(top_m - resolution.deep_m, 0.0)
    length = box[0][2] - bottom
    if length <= 0.0:
        if box[0][2] <= 0.0:
            return None  # the box already reaches the block's bottom
        raise MeshError(
            f"deep_m ({resolution.deep_m} m) must reach below the working region, whose "
            f"bottom lies {top_m - box[0][2]:.6g} m below the top surface"
        )
    return (length, resolution.deep_cell_m)


def resolved_region(
    resolution: Resolution, block_m: Sequence[float], electrodes: Sequence[_Electrode]
) -> Box:
    """Where the graded grid resolves a crater: the working box, down to the bottom of its deep
    tier when it has one (m)."""
    lo, hi = working_region(resolution, block_m, electrodes)
    tier = deep_tier(resolution, (lo, hi), float(block_m[2]))
    if tier is None:
        return (lo, hi)
    return ((lo[0], lo[1], lo[2] - tier[0]), hi)


def graded_grid(
    resolution: Resolution, block_m: Sequence[float], electrodes: Sequence[_Electrode]
) -> Grid:
    """The scene's graded grid over the block (Lx, Ly, Lz) in m (origin at 0)."""
    lo, hi = working_region(resolution, block_m, electrodes)
    return Grid.graded(
        lo,
        hi,
        resolution.fine_spacing_m,
        growth=resolution.growth,
        max_cell_m=resolution.max_cell_m,
        top_cell_m=resolution.surface_m,
        bottom_tier_m=deep_tier(resolution, (lo, hi), float(block_m[2])),
        size_m=(float(block_m[0]), float(block_m[1]), float(block_m[2])),
    )
