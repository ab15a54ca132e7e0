"""Vertical line segments in one image (paper Sec 2.1).

"Vertical line segments are extracted from edges obtained by applying a horizontal differential
operator to the input image." The pipeline of :func:`extract_vertical_segments`:

1. horizontal derivative ``g = Sobel_x(I)`` (``cv2.Sobel``, ksize 3, unnormalized: a sharp step of
   ``h`` grey levels gives ``|g| = 4 h``);
2. non-maximum suppression along each row, separately for each sign of ``g``, and the sub-pixel
   column of each maximum from a parabola through ``|g|`` at the three columns ``c-1, c, c+1``
   (exact for a box-filtered, i.e. anti-aliased, step);
3. linking edge pixels of the same sign row by row into vertical runs that drift by at most
   ``max_drift`` px per row and may skip up to ``max_gap`` rows;
4. a straight-line fit ``u = u0 + slope (v - v_mid)`` over each run's sub-pixel points, splitting
   runs that are not straight at their point farthest from the chord (Douglas-Peucker), and
   keeping the straight pieces that are long enough and close enough to vertical. End pixels
   weaker than half the piece's mean response are trimmed first: Sobel's vertical smoothing
   extends an edge by one row at each end, at a quarter of its response.

The fit regresses ``u`` on ``v`` (rows are exact, columns carry the noise); for near-vertical lines
this is the total-least-squares line to first order in the slope.

Image convention (DESIGN §3): ``u`` column to the right, ``v`` row down, pixel centres at integer
coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numba import njit

from ..errors import ConfigError, ImageError, InputError, expected

__all__ = ["SegmentConfig", "Segments", "extract_vertical_segments"]


@dataclass(frozen=True)
class SegmentConfig:
    """Parameters of :func:`extract_vertical_segments`; the defaults suit 640×480 indoor images.

    Attributes
    ----------
    gradient_threshold : minimum ``|Sobel_x|`` of an edge pixel, in image intensity units times the
        Sobel gain (a sharp step of ``h`` grey levels gives ``4 h``; 40 = a 10-level step in an 8-bit
        image). Scale it with the intensity range of float images.
    min_length : minimum segment length ``v_bottom - v_top`` [px].
    max_drift : maximum column change between consecutive edge pixels of a run [px per row].
    max_gap : number of missing rows a run may bridge (0 = every row must have an edge pixel).
    max_residual : maximum ``|u - fitted u|`` of any edge pixel of a straight segment [px];
        runs that deviate more are split.
    max_angle : maximum angle of a segment from the vertical [rad].
    """

    gradient_threshold: float = 40.0
    min_length: float = 16.0
    max_drift: int = 1
    max_gap: int = 1
    max_residual: float = 1.0
    max_angle: float = float(np.deg2rad(10.0))

    def __post_init__(self) -> None:
        where = "SegmentConfig"
        if not self.gradient_threshold > 0:
            raise ConfigError(
                expected("a positive number", self.gradient_threshold, where=f"{where}.gradient_threshold")
            )
        if not self.min_length >= 1:
            raise ConfigError(expected("a number >= 1 [px]", self.min_length, where=f"{where}.min_length"))
        for name in ("max_drift", "max_gap"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ConfigError(expected("a non-negative integer", value, where=f"{where}.{name}"))
        if not self.max_residual > 0:
            raise ConfigError(expected("a positive number [px]", self.max_residual, where=f"{where}.max_residual"))
        if not 0 < self.max_angle < np.pi / 2:
            raise ConfigError(expected("an angle in (0, pi/2) [rad]", self.max_angle, where=f"{where}.max_angle"))


@dataclass(frozen=True, eq=False)
class Segments:
    """N vertical line segments of one image, as a struct of arrays.

    Each segment is the line ``u(v) = u + slope (v - v_mid)``, ``v_mid = (v_top + v_bottom) / 2``,
    for ``v_top <= v <= v_bottom``.

    Attributes
    ----------
    u : (N,) float64, sub-pixel column at the segment's middle row ``v_mid`` [px].
    slope : (N,) float64, ``du/dv`` [px/px].
    v_top, v_bottom : (N,) float64, first and last row [px], ``v_top < v_bottom``.
    polarity : (N,) int8, +1 where the image goes dark to bright from left to right (``Sobel_x > 0``),
        -1 otherwise.
    contrast : (N,) float64, mean ``|Sobel_x|`` over the segment's edge pixels (intensity units × 4
        for a step, see :class:`SegmentConfig`).
    n_pixels : (N,) int64, number of edge pixels the segment was fitted to.
    pixel_offsets : (N + 1,) int64, segment ``i`` owns rows ``pixel_offsets[i]:pixel_offsets[i+1]``
        of ``pixel_uv``.
    pixel_uv : (P, 2) int32, integer ``(u, v)`` of the edge pixels of all segments.
    """

    u: np.ndarray
    slope: np.ndarray
    v_top: np.ndarray
    v_bottom: np.ndarray
    polarity: np.ndarray
    contrast: np.ndarray
    n_pixels: np.ndarray
    pixel_offsets: np.ndarray = field(repr=False)
    pixel_uv: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        n = np.shape(self.u)[0] if np.ndim(self.u) == 1 else -1
        for name in ("u", "slope", "v_top", "v_bottom", "polarity", "contrast", "n_pixels"):
            if np.shape(getattr(self, name)) != (n,):
                raise InputError(expected(f"shape ({n},)", np.shape(getattr(self, name)), where=f"Segments.{name}"))
        if np.shape(self.pixel_offsets) != (n + 1,):
            raise InputError(
                expected(f"shape ({n + 1},)", np.shape(self.pixel_offsets), where="Segments.pixel_offsets")
            )
        if np.ndim(self.pixel_uv) != 2 or np.shape(self.pixel_uv)[1] != 2:
            raise InputError(expected("shape (P, 2)", np.shape(self.pixel_uv), where="Segments.pixel_uv"))
        if not np.all(self.v_bottom > self.v_top):
            raise InputError(
                expected("v_bottom > v_top for every segment", "a segment without length", where="Segments")
            )

    @classmethod
    def empty(cls) -> Segments:
        """No segments."""
        return cls(
            u=np.zeros(0), slope=np.zeros(0), v_top=np.zeros(0), v_bottom=np.zeros(0),
            polarity=np.zeros(0, np.int8), contrast=np.zeros(0), n_pixels=np.zeros(0, np.int64),
            pixel_offsets=np.zeros(1, np.int64), pixel_uv=np.zeros((0, 2), np.int32),
        )  # fmt: skip

    @classmethod
    def from_lines(
        cls,
        u: np.ndarray,
        v_top: np.ndarray,
        v_bottom: np.ndarray,
        *,
        slope: np.ndarray | float = 0.0,
        polarity: np.ndarray | int = 1,
        contrast: np.ndarray | float = 100.0,
    ) -> Segments:
        """Segments from line parameters, with one pixel per integer row (rounded column).

        ``u`` (N,) is the column at the middle row ``(v_top + v_bottom) / 2`` [px]; scalars
        broadcast. Used to describe segments known from geometry (simulation, tests).
        """
        u = np.atleast_1d(np.asarray(u, np.float64))
        n = u.shape[0]
        v_top = np.broadcast_to(np.asarray(v_top, np.float64), (n,)).copy()
        v_bottom = np.broadcast_to(np.asarray(v_bottom, np.float64), (n,)).copy()
        slope = np.broadcast_to(np.asarray(slope, np.float64), (n,)).copy()
        rows = [np.arange(np.ceil(t), np.floor(b) + 1) for t, b in zip(v_top, v_bottom, strict=True)]
        counts = np.array([len(r) for r in rows], np.int64)
        v_all = np.concatenate(rows) if n else np.zeros(0)
        seg = np.repeat(np.arange(n), counts)
        u_all = u[seg] + slope[seg] * (v_all - 0.5 * (v_top[seg] + v_bottom[seg]))
        return cls(
            u=u, slope=slope, v_top=v_top, v_bottom=v_bottom,
            polarity=np.broadcast_to(np.asarray(polarity, np.int8), (n,)).copy(),
            contrast=np.broadcast_to(np.asarray(contrast, np.float64), (n,)).copy(),
            n_pixels=counts,
            pixel_offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            pixel_uv=np.stack([np.rint(u_all), v_all], axis=1).astype(np.int32),
        )  # fmt: skip

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @property
    def length(self) -> np.ndarray:
        """(N,) float64, ``v_bottom - v_top`` [px] (the ``len`` of Eq 18)."""
        return self.v_bottom - self.v_top

    @property
    def v_mid(self) -> np.ndarray:
        """(N,) float64, middle row ``(v_top + v_bottom) / 2`` [px]."""
        return 0.5 * (self.v_top + self.v_bottom)

    @property
    def orientation(self) -> np.ndarray:
        """(N,) float64, signed angle from the vertical ``atan(du/dv)`` [rad]; positive when the
        bottom end lies to the right of the top end."""
        return np.arctan(self.slope)

    def u_at(self, v: np.ndarray | float) -> np.ndarray:
        """Column of each segment's line at row(s) ``v`` [px] (``v`` broadcasts against (N,))."""
        return self.u + self.slope * (np.asarray(v, np.float64) - self.v_mid)

    def pixels(self, i: int) -> np.ndarray:
        """(n, 2) int32, integer ``(u, v)`` of the edge pixels segment ``i`` was fitted to, top to
        bottom (index an image with ``image[p[:, 1], p[:, 0]]``)."""
        if not -len(self) <= i < len(self):
            raise IndexError(expected(f"a segment index in [0, {len(self)})", i, where="Segments.pixels"))
        i = int(i) % len(self)
        return self.pixel_uv[self.pixel_offsets[i] : self.pixel_offsets[i + 1]]

    def subset(self, mask_or_idx: np.ndarray) -> Segments:
        """The segments selected by a boolean (N,) mask or an integer index array, in that order."""
        sel = np.asarray(mask_or_idx)
        if sel.dtype == bool:
            if sel.shape != (len(self),):
                raise IndexError(
                    expected(f"a boolean mask of shape ({len(self)},)", sel.shape, where="Segments.subset")
                )
            sel = np.flatnonzero(sel)
        sel = sel.astype(np.int64).reshape(-1)
        starts, stops = self.pixel_offsets[sel], self.pixel_offsets[sel + 1]
        counts = stops - starts
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        pix = np.repeat(starts - offsets[:-1], counts) + np.arange(offsets[-1])
        return Segments(
            u=self.u[sel], slope=self.slope[sel], v_top=self.v_top[sel], v_bottom=self.v_bottom[sel],
            polarity=self.polarity[sel], contrast=self.contrast[sel], n_pixels=self.n_pixels[sel],
            pixel_offsets=offsets, pixel_uv=np.take(self.pixel_uv, pix, axis=0),
        )  # fmt: skip


def extract_vertical_segments(image: np.ndarray, config: SegmentConfig = SegmentConfig(), *,
                              sobel: np.ndarray | None = None) -> Segments:
    """Vertical line segments of a grayscale image (paper Sec 2.1), sorted by column ``u``.

    Parameters
    ----------
    image : (H, W) uint8 or float grayscale, H, W >= 3, finite.
    config : detection parameters.
    sobel : for a uint8 ``image``, its x-Sobel derivative if already computed (``cv2.Sobel(image,
        cv2.CV_16S, 1, 0, ksize=3)``, (H, W) int16); ignored for float images.

    Returns
    -------
    Segments, possibly empty.

    Raises
    ------
    ImageError
        If ``image`` is not a finite 2-D uint8/float array of at least 3×3 pixels.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ImageError(expected("a 2-D grayscale image (H, W)", img.shape, where="image"))
    if img.shape[0] < 3 or img.shape[1] < 3:
        raise ImageError(expected("an image of at least 3x3 pixels", img.shape, where="image"))
    if img.dtype == np.uint8:
        if sobel is not None and (np.shape(sobel) != img.shape or np.asarray(sobel).dtype != np.int16):
            raise ImageError(expected(f"an int16 x-Sobel of the image's shape {img.shape}",
                                      f"{np.asarray(sobel).dtype} {np.shape(sobel)}", where="sobel"))
        gx = cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3) if sobel is None else sobel  # |gx| <= 4 * 255
        threshold = np.int16(min(np.ceil(config.gradient_threshold), 32767))  # integer compare vectorizes
    elif np.issubdtype(img.dtype, np.floating):
        if not np.all(np.isfinite(img)):
            raise ImageError(expected("finite pixel values", "NaN or inf", where="image"))
        gx = cv2.Sobel(img.astype(np.float32, copy=False), cv2.CV_32F, 1, 0, ksize=3)
        threshold = np.float32(config.gradient_threshold)
    else:
        raise ImageError(expected("dtype uint8 or float", str(img.dtype), where="image"))

    edges = _detect_and_link(gx, threshold, int(config.max_drift), int(config.max_gap))
    u, slope, v_top, v_bottom, polarity, contrast, offsets, pixel_uv = _fit_segments(
        gx, *edges, float(config.min_length), float(config.max_residual), float(np.tan(config.max_angle))
    )
    order = np.argsort(u, kind="stable")  # by column, each segment's pixels moved along in one pass
    offsets, pixel_uv = _reorder_pixels(offsets, pixel_uv, order)
    return Segments(
        u=u[order], slope=slope[order], v_top=v_top[order], v_bottom=v_bottom[order], polarity=polarity[order],
        contrast=contrast[order], n_pixels=np.diff(offsets), pixel_offsets=offsets, pixel_uv=pixel_uv,
    )  # fmt: skip


@njit(cache=True)
def _reorder_pixels(offsets, pixel_uv, order):  # pragma: no cover - numba
    """The pixel blocks of segments ``order[0], order[1], …`` one after the other: their offsets (int64) and
    pixels (what :meth:`Segments.subset` makes of them)."""
    n = order.shape[0]
    out_offsets = np.zeros(n + 1, np.int64)
    for i in range(n):
        out_offsets[i + 1] = out_offsets[i] + offsets[order[i] + 1] - offsets[order[i]]
    out = np.empty((out_offsets[n], 2), pixel_uv.dtype)
    for i in range(n):
        a = offsets[order[i]]
        for j in range(out_offsets[i + 1] - out_offsets[i]):
            out[out_offsets[i] + j, 0] = pixel_uv[a + j, 0]
            out[out_offsets[i] + j, 1] = pixel_uv[a + j, 1]
    return out_offsets, out


@njit(cache=True)
def _detect_and_link(gx, threshold, max_drift, max_gap):
    """Row-wise NMS and linking of the maxima into vertical runs (steps 2-3).

    An edge pixel continues the run of a same-sign edge pixel directly above it if there is one;
    otherwise the nearest such run end within ``max_drift`` px per row, up to ``max_gap`` missing
    rows up; otherwise it starts a run. Each run takes at most one pixel per row.

    Only ``(v, col)`` and the next pixel of the run are stored per edge pixel (everything else is
    read again from ``gx`` for the few long runs): touching little fresh memory matters here.

    Returns the edge pixels in row-major order ``(v, col)``, the next pixel of the same run (-1 at
    its end) and, per run, its first pixel, first row and last row.
    """
    H, W = gx.shape
    cap = H * W
    ev = np.empty(cap, np.int32)
    ecol = np.empty(cap, np.int32)
    nxt = np.empty(cap, np.int32)
    head = np.empty(cap, np.int32)
    tail = np.empty(cap, np.int32)
    first_row = np.empty(cap, np.int32)
    last_row = np.empty(cap, np.int32)
    # Candidate predecessors other than the one directly above, cheapest first:
    # (rows up, column offset) by growing drift, then bridged gaps.
    n_off = 0
    off_k = np.empty((max_gap + 1) * (2 * max_drift * (max_gap + 1) + 1), np.int64)
    off_dc = np.empty_like(off_k)
    for k in range(1, max_gap + 2):
        for a in range(0, k * max_drift + 1):
            for sgn in (-1, 1):
                if (a == 0 and sgn == 1) or (k == 1 and a == 0):
                    continue
                off_k[n_off] = k
                off_dc[n_off] = sgn * a
                n_off += 1
    # ring[v % n_ring, margin + col] = 2 run + (sign > 0) of the edge pixel at (v, col) of a recent
    # row, or -1; the margin spares bound checks.
    n_ring = max_gap + 2
    margin = (max_gap + 1) * max_drift
    ring = np.full((n_ring, W + 2 * margin), -1, np.int32)
    slot_up = np.empty(max_gap + 2, np.int64)  # ring row of row v - k
    # the row's maxima as bytes read 8 at a time: the compaction skips the words holding none (edge pixels are a
    # few percent of a row; the branch-free pass over every column took ~0.1 ms of an image's 0.34)
    n_words = (W + 7) // 8
    is_max = np.zeros(8 * n_words, np.uint8)
    words = is_max.view(np.uint64)
    run_of = np.empty(W, np.int32)  # run of each edge pixel of the current row
    n_e = 0
    n_ch = 0
    for v in range(H):
        row = gx[v]
        # Branch-free NMS (vectorizes), then the compaction of the maxima; ties go to the left pixel of a plateau.
        for c in range(1, W - 1):
            g, gl, gr = row[c], row[c - 1], row[c + 1]
            is_max[c] = ((g >= threshold) & (g > gl) & (g >= gr)) | ((g <= -threshold) & (g < gl) & (g <= gr))
        row_start = n_e
        for wd in range(n_words):  # columns 0 and W - 1 and the padding hold no maximum
            if words[wd] != 0:
                for c in range(8 * wd, 8 * wd + 8):
                    ecol[n_e] = c
                    n_e += is_max[c]
        n_row = n_e - row_start
        for k in range(max_gap + 2):
            slot_up[k] = (v - k) % n_ring
        for e in range(n_row):
            run_of[e] = -1
        if v >= 1:  # first every direct continuation, so that a drifting pixel cannot steal it
            above = slot_up[1]
            for e in range(n_row):
                c = ecol[row_start + e]
                code = ring[above, margin + c]
                if code >= 0 and (code & 1) == (row[c] > 0) and last_row[code >> 1] == v - 1:
                    run_of[e] = code >> 1
        for e in range(n_row):
            c = ecol[row_start + e]
            ch = run_of[e]
            if ch < 0:
                positive = row[c] > 0
                for o in range(n_off):
                    vv = v - off_k[o]
                    if vv < 0:
                        break
                    code = ring[slot_up[off_k[o]], margin + c + off_dc[o]]
                    if code >= 0 and (code & 1) == positive and last_row[code >> 1] == vv:
                        ch = code >> 1
                        break
            if ch < 0:
                ch = n_ch
                n_ch += 1
                head[ch] = row_start + e
                first_row[ch] = v
            else:
                nxt[tail[ch]] = row_start + e
            run_of[e] = ch
            tail[ch] = row_start + e
            last_row[ch] = v
            ev[row_start + e] = v
            nxt[row_start + e] = -1
        slot = slot_up[0]
        ring[slot, :] = -1
        for e in range(n_row):
            c = ecol[row_start + e]
            ring[slot, margin + c] = 2 * run_of[e] + (row[c] > 0)
    return ev[:n_e], ecol[:n_e], nxt[:n_e], head[:n_ch], first_row[:n_ch], last_row[:n_ch]


@njit(cache=True)
def _fit_segments(gx, ev, ecol, nxt, head, first_row, last_row, min_length, max_residual, max_slope):
    """Straight-line fits of the runs, split where not straight (step 4); see the module docstring.

    Returns the segments' ``u, slope, v_top, v_bottom, polarity, contrast, pixel_offsets, pixel_uv``.
    """
    H = gx.shape[0]
    n_long = 0
    n_pix_max = 0
    for ch in range(head.shape[0]):
        if last_row[ch] - first_row[ch] >= min_length:
            n_long += 1
            n_pix_max += last_row[ch] - first_row[ch] + 1  # at most one pixel per row
    cap = max(1, n_pix_max // 2)  # a segment has two pixels or more
    out_u = np.empty(cap, np.float64)
    out_slope = np.empty(cap, np.float64)
    v_top = np.empty(cap, np.float64)
    v_bottom = np.empty(cap, np.float64)
    polarity = np.empty(cap, np.int8)
    contrast = np.empty(cap, np.float64)
    offsets = np.zeros(cap + 1, np.int64)
    pix = np.empty((n_pix_max, 2), np.int32)
    # the current run, top to bottom: row, column, sub-pixel column, |gx|
    rv = np.empty(H, np.int32)
    rc = np.empty(H, np.int32)
    ru = np.empty(H, np.float64)
    rg = np.empty(H, np.float64)
    stack_lo = np.empty(H + 1, np.int64)
    stack_hi = np.empty(H + 1, np.int64)
    n_out = 0
    for ch in range(head.shape[0]):
        if last_row[ch] - first_row[ch] < min_length:
            continue
        n = 0
        e = head[ch]
        sign = 1.0 if gx[ev[e], ecol[e]] > 0 else -1.0
        while e >= 0:
            v, c = ev[e], ecol[e]
            a = sign * gx[v, c - 1]
            b = sign * gx[v, c]
            d = sign * gx[v, c + 1]
            off = 0.5 * (a - d) / (a - 2.0 * b + d)  # vertex of the parabola through (a, b, d)
            rv[n] = v
            rc[n] = c
            ru[n] = c + min(0.5, max(-0.5, off))
            rg[n] = b
            n += 1
            e = nxt[e]
        n_stack = 1
        stack_lo[0] = 0
        stack_hi[0] = n
        while n_stack > 0:
            n_stack -= 1
            lo = stack_lo[n_stack]
            hi = stack_hi[n_stack]
            # Drop end pixels weaker than half the mean response: Sobel's vertical smoothing
            # reaches one row past the end of an edge, at a quarter of its response.
            half = 0.0
            for k in range(lo, hi):
                half += rg[k]
            half *= 0.5 / (hi - lo)
            while hi - lo > 1 and rg[lo] < half:
                lo += 1
            while hi - lo > 1 and rg[hi - 1] < half:
                hi -= 1
            v0 = rv[lo]
            v1 = rv[hi - 1]
            if v1 - v0 < min_length:
                continue
            mv = 0.0
            mu = 0.0
            for k in range(lo, hi):
                mv += rv[k]
                mu += ru[k]
            mv /= hi - lo
            mu /= hi - lo
            svv = 0.0
            svu = 0.0
            for k in range(lo, hi):
                svv += (rv[k] - mv) ** 2
                svu += (rv[k] - mv) * (ru[k] - mu)
            slope = svu / svv
            worst = 0.0
            for k in range(lo, hi):
                worst = max(worst, abs(ru[k] - mu - slope * (rv[k] - mv)))
            if worst <= max_residual:
                if abs(slope) <= max_slope:
                    out_u[n_out] = mu + slope * (0.5 * (v0 + v1) - mv)
                    out_slope[n_out] = slope
                    v_top[n_out] = v0
                    v_bottom[n_out] = v1
                    polarity[n_out] = np.int8(sign)
                    at = offsets[n_out]
                    total = 0.0
                    for k in range(lo, hi):
                        total += rg[k]
                        pix[at + k - lo, 0] = rc[k]
                        pix[at + k - lo, 1] = rv[k]
                    contrast[n_out] = total / (hi - lo)
                    offsets[n_out + 1] = at + hi - lo
                    n_out += 1
                continue
            # Not straight: split at the point farthest from the chord (Douglas-Peucker).
            chord = (ru[hi - 1] - ru[lo]) / (v1 - v0)
            split = lo + 1
            far = -1.0
            for k in range(lo + 1, hi - 1):
                dist = abs(ru[k] - ru[lo] - chord * (rv[k] - v0))
                if dist > far:
                    far = dist
                    split = k
            stack_lo[n_stack] = lo
            stack_hi[n_stack] = split
            stack_lo[n_stack + 1] = split
            stack_hi[n_stack + 1] = hi
            n_stack += 2

    return (out_u[:n_out], out_slope[:n_out], v_top[:n_out], v_bottom[:n_out], polarity[:n_out],
            contrast[:n_out], offsets[: n_out + 1], pix[: offsets[n_out]])  # fmt: skip
