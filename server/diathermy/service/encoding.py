"""Arrays on the wire: msgpack maps of raw little-endian bytes with shape and dtype, or npz."""

from __future__ import annotations

import io
from typing import Any, Literal

import msgpack
import numpy as np
from scipy.ndimage import map_coordinates

WireDtype = Literal["float16", "float32"]


def encode_array(a: np.ndarray, dtype: str | None = None) -> dict[str, Any]:
    """``{"shape", "dtype", "data"}``: C-order little-endian bytes; floats cast to ``dtype``.

    Values beyond the range of ``dtype`` become +-inf (float16 tops out at 65504).
    """
    a = np.asarray(a)
    if dtype is not None and a.dtype.kind == "f":
        with np.errstate(over="ignore"):  # beyond float16's range is +-inf, as IEEE says
            a = a.astype(dtype)
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    return {"shape": list(a.shape), "dtype": a.dtype.str, "data": a.tobytes()}


def decode_array(d: dict[str, Any]) -> np.ndarray:
    """Inverse of ``encode_array``."""
    return np.frombuffer(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"])


def pack(obj: Any) -> bytes:
    """msgpack with bin types for bytes."""
    return msgpack.packb(obj, use_bin_type=True)


def unpack(data: bytes) -> Any:
    return msgpack.unpackb(data, raw=False)


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed .npz of named arrays."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]
    return buf.getvalue()


def sample_nodal(
    values: np.ndarray,
    points_m: np.ndarray,
    *,
    origin_m: tuple[float, float, float],
    spacing_m: tuple[float, float, float] | None,
    axes_m: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Trilinear samples of a grid field (nz, ny, nx[, c]) at points (n, 3) in m -> (n[, c]).

    A uniform grid gives ``spacing_m``; a graded one its node coordinates ``axes_m`` (x, y, z),
    where each point's fractional node index comes from the coordinates (binary search).
    """
    pts = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if axes_m is not None:
        idx = np.column_stack(
            [np.interp(pts[:, c], a, np.arange(len(a))) for c, a in enumerate(axes_m)]
        )
    else:
        assert spacing_m is not None, "sample_nodal needs spacing_m or axes_m"
        idx = (pts - np.asarray(origin_m)) / np.asarray(spacing_m)  # (n, 3) as (i, j, k)
    coords = idx[:, ::-1].T  # (3, n) as (k, j, i)
    if values.ndim == 3:
        return map_coordinates(values, coords, order=1, mode="nearest")
    return np.stack(
        [map_coordinates(values[..., c], coords, order=1, mode="nearest") for c in range(3)],
        axis=-1,
    )
