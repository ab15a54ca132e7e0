"""Segment-based stereo matching by dynamic programming (paper Sec 2.1, Eq 18).

"To match segments in the stereo images, we define similarity which consists of overlapping ratio,
and orientation and length similarity, and then dynamic programming method is applied to
determine the best matching by comparing the similarity."

Rectified images, left camera the reference: a pair ``(i, j)`` has disparity
``d = u_left - u_right > 0`` (DESIGN §3), measured at the middle row of the pair's vertical overlap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import ConfigError, expected
from .segments import Segments

__all__ = ["MatchConfig", "SegmentPairs", "match_segments"]


@dataclass(frozen=True)
class MatchConfig:
    """Parameters of :func:`match_segments`.

    Attributes
    ----------
    min_disparity, max_disparity : accepted disparity range ``[min, max]`` of a pair [px] (hard).
    same_polarity : a pair must have equal polarity (hard).
    min_overlap : minimum vertical overlap ratio, overlap / shorter length (hard), in (0, 1].
    max_orientation_difference : maximum ``|orientation_l - orientation_r|`` [rad] (hard); the
        orientation similarity falls linearly from 1 (equal) to 0 at this difference.
    weight_overlap, weight_orientation, weight_length : weights of the three similarity terms
        (normalized by their sum).
    min_similarity : minimum similarity of a candidate pair, in [0, 1].
    occlusion_cost : DP cost of leaving a segment unmatched; matching a candidate costs
        ``1 - similarity``, so a candidate can only win against two skips if
        ``1 - similarity < 2 occlusion_cost``.
    """

    min_disparity: float = 0.0
    max_disparity: float = 64.0
    same_polarity: bool = True
    min_overlap: float = 0.5
    max_orientation_difference: float = float(np.deg2rad(5.0))
    weight_overlap: float = 1.0
    weight_orientation: float = 1.0
    weight_length: float = 1.0
    min_similarity: float = 0.5
    occlusion_cost: float = 0.25

    def __post_init__(self) -> None:
        where = "MatchConfig"
        if not (np.isfinite(self.min_disparity) and np.isfinite(self.max_disparity)):
            raise ConfigError(
                expected("finite disparities", (self.min_disparity, self.max_disparity), where=f"{where}.disparity")
            )
        if not self.max_disparity > self.min_disparity:
            raise ConfigError(
                expected(f"max_disparity > min_disparity = {self.min_disparity}", self.max_disparity,
                         where=f"{where}.max_disparity")
            )  # fmt: skip
        if not 0 < self.min_overlap <= 1:
            raise ConfigError(expected("a ratio in (0, 1]", self.min_overlap, where=f"{where}.min_overlap"))
        if not self.max_orientation_difference > 0:
            raise ConfigError(
                expected("a positive angle [rad]", self.max_orientation_difference,
                         where=f"{where}.max_orientation_difference")
            )  # fmt: skip
        weights = (self.weight_overlap, self.weight_orientation, self.weight_length)
        if not (all(w >= 0 for w in weights) and sum(weights) > 0):
            raise ConfigError(expected("non-negative weights with a positive sum", weights, where=f"{where}.weight_*"))
        if not 0 <= self.min_similarity <= 1:
            raise ConfigError(expected("a number in [0, 1]", self.min_similarity, where=f"{where}.min_similarity"))
        if not self.occlusion_cost > 0:
            raise ConfigError(expected("a positive number", self.occlusion_cost, where=f"{where}.occlusion_cost"))


@dataclass(frozen=True, eq=False)
class SegmentPairs:
    """M matched left/right segment pairs, as a struct of arrays.

    Attributes
    ----------
    left_index, right_index : (M,) int64, indices into the left and right :class:`Segments`.
    similarity : (M,) float64, weighted similarity in [0, 1].
    overlap : (M,) float64, vertical overlap ratio, overlap / shorter length, in (0, 1].
    orientation_similarity : (M,) float64, in [0, 1].
    length_similarity : (M,) float64, ``min(len_l, len_r) / max(len_l, len_r)`` (Eq 18).
    u_left, u_right : (M,) float64, columns at the middle row of the vertical overlap [px].
    v_top, v_bottom : (M,) float64, first and last row of the vertical overlap [px].
    length_left, length_right : (M,) float64, segment lengths [px].
    """

    left_index: np.ndarray
    right_index: np.ndarray
    similarity: np.ndarray
    overlap: np.ndarray
    orientation_similarity: np.ndarray
    length_similarity: np.ndarray
    u_left: np.ndarray
    u_right: np.ndarray
    v_top: np.ndarray
    v_bottom: np.ndarray
    length_left: np.ndarray
    length_right: np.ndarray

    def __len__(self) -> int:
        return int(self.left_index.shape[0])

    @property
    def disparity(self) -> np.ndarray:
        """(M,) float64, ``u_left - u_right`` at the middle row of the overlap [px]."""
        return self.u_left - self.u_right

    def subset(self, mask_or_idx: np.ndarray) -> SegmentPairs:
        """The pairs selected by a boolean (M,) mask or an integer index array."""
        sel = np.asarray(mask_or_idx)
        if sel.dtype == bool and sel.shape != (len(self),):
            raise IndexError(
                expected(f"a boolean mask of shape ({len(self)},)", sel.shape, where="SegmentPairs.subset")
            )
        return SegmentPairs(**{name: getattr(self, name)[sel] for name in self.__dataclass_fields__})


def match_segments(left: Segments, right: Segments, config: MatchConfig = MatchConfig()) -> SegmentPairs:
    """Match vertical segments of a rectified stereo pair (paper Sec 2.1), sorted by ``u_left``.

    1. **Candidates.** Every left/right pair that passes the hard constraints — same polarity,
       disparity in ``[min_disparity, max_disparity]``, vertical overlap ratio ``>= min_overlap``,
       orientation difference ``<= max_orientation_difference`` — gets the similarity

       ``s = (w_o r_o + w_θ s_θ + w_ℓ ℓ_s) / (w_o + w_θ + w_ℓ)``

       with ``r_o`` = overlap / shorter length, ``s_θ = 1 - |θ_l - θ_r| / max_orientation_difference``
       and the length similarity ``ℓ_s`` of Eq 18; it is a candidate if ``s >= min_similarity``.
    2. **Dynamic programming per band of rows.** The segments' top and bottom rows cut the image
       into elementary bands, inside which every segment is either present over the whole band
       or absent. In each band the present left and right segments are ordered by their column at
       the band's middle row, and a scanline DP (Ohta-Kanade, Cox et al.) aligns the two ordered
       lists with the moves *match* (cost ``1 - s``, candidates only), *skip left* and *skip right*
       (cost ``occlusion_cost`` each). This is the ordering constraint, applied exactly where it
       makes sense: among segments present on the same rows. Segments stacked above one another
       never constrain each other.
    3. **Consolidation.** Each pair matched in a band earns ``band height × s``. Pairs are
       accepted in decreasing order of their total, skipping any pair that reuses a segment or
       crosses an accepted pair on the rows where both are present (opposite left-right order in
       the two images). So each segment is used at most once and the ordering constraint holds
       between every two accepted pairs that overlap vertically.

    Parameters
    ----------
    left, right : segments of the left and right images.
    config : matching parameters.

    Returns
    -------
    SegmentPairs, possibly empty.
    """
    s, overlap, s_orient, s_length, cand = _candidates(left, right, config)
    il, ir = np.nonzero(cand)
    if il.size == 0:
        return _pairs(left, right, np.zeros(0, np.int64), np.zeros(0, np.int64), s, overlap, s_orient, s_length)
    sim = np.where(cand, s, np.nan)
    in_l, in_r = np.flatnonzero(cand.any(axis=1)), np.flatnonzero(cand.any(axis=0))
    cuts = np.unique(np.concatenate([left.v_top[in_l], left.v_bottom[in_l], right.v_top[in_r], right.v_bottom[in_r]]))
    top, bottom = cuts[:-1], cuts[1:]
    order_l, count_l = _band_order(left, in_l, top, bottom)
    order_r, count_r = _band_order(right, in_r, top, bottom)
    score = _band_dp(sim, order_l, count_l, order_r, count_r, bottom - top, float(config.occlusion_cost))
    li, ri = np.nonzero(score > 0)
    rank = np.lexsort((-sim[li, ri], -score[li, ri]))
    li, ri = li[rank], ri[rank]
    keep = _consolidate(
        li, ri, left.u, left.slope, left.v_top, left.v_bottom, right.u, right.slope, right.v_top, right.v_bottom
    )
    li, ri = li[keep], ri[keep]
    pairs = _pairs(left, right, li, ri, s, overlap, s_orient, s_length)
    return pairs.subset(np.argsort(pairs.u_left, kind="stable"))


def _candidates(left: Segments, right: Segments, config: MatchConfig):
    """(NL, NR) similarity, its three terms, and the candidate mask (step 1 of match_segments)."""
    len_l, len_r = left.length[:, None], right.length[None, :]
    top = np.maximum(left.v_top[:, None], right.v_top[None, :])
    bottom = np.minimum(left.v_bottom[:, None], right.v_bottom[None, :])
    shorter, longer = np.minimum(len_l, len_r), np.maximum(len_l, len_r)
    overlap = np.clip(bottom - top, 0.0, None) / shorter
    v_mid = 0.5 * (top + bottom)
    disparity = left.u_at(v_mid.T).T - right.u_at(v_mid)
    d_theta = np.abs(left.orientation[:, None] - right.orientation[None, :])
    s_orient = np.clip(1.0 - d_theta / config.max_orientation_difference, 0.0, 1.0)
    s_length = shorter / longer  # Eq 18
    w = np.array([config.weight_overlap, config.weight_orientation, config.weight_length])
    s = (w[0] * overlap + w[1] * s_orient + w[2] * s_length) / w.sum()
    cand = (
        (bottom > top)
        & (overlap >= config.min_overlap)
        & (disparity >= config.min_disparity)
        & (disparity <= config.max_disparity)
        & (d_theta <= config.max_orientation_difference)
        & (s >= config.min_similarity)
    )
    if config.same_polarity:
        cand &= left.polarity[:, None] == right.polarity[None, :]
    return s, overlap, s_orient, s_length, cand


def _pairs(left, right, li, ri, s, overlap, s_orient, s_length) -> SegmentPairs:
    top = np.maximum(left.v_top[li], right.v_top[ri])
    bottom = np.minimum(left.v_bottom[li], right.v_bottom[ri])
    v_mid = 0.5 * (top + bottom)
    return SegmentPairs(
        left_index=li.astype(np.int64), right_index=ri.astype(np.int64),
        similarity=s[li, ri], overlap=overlap[li, ri], orientation_similarity=s_orient[li, ri],
        length_similarity=s_length[li, ri],
        u_left=left.u[li] + left.slope[li] * (v_mid - left.v_mid[li]),
        u_right=right.u[ri] + right.slope[ri] * (v_mid - right.v_mid[ri]),
        v_top=top, v_bottom=bottom, length_left=left.length[li], length_right=right.length[ri],
    )  # fmt: skip


def _band_order(segments: Segments, idx: np.ndarray, top: np.ndarray, bottom: np.ndarray):
    """For each band ``[top[b], bottom[b]]``: the segments of ``idx`` present over the whole band,
    ordered by their column at its middle row, (B, len(idx)) padded; and their number, (B,)."""
    present = (segments.v_top[idx] <= top[:, None]) & (segments.v_bottom[idx] >= bottom[:, None])
    u = segments.u_at(0.5 * (top + bottom)[:, None])[:, idx]
    order = np.argsort(np.where(present, u, np.inf), axis=1, kind="stable")
    return idx[order], present.sum(axis=1)


@njit(cache=True)
def _band_dp(sim, order_l, count_l, order_r, count_r, height, occlusion_cost):
    """Per-band scanline DP (step 2 of match_segments); returns the (NL, NR) band-height-weighted
    similarity each pair earned. ``sim`` is NaN where a pair is not a candidate; band ``b`` holds
    the left segments ``order_l[b, :count_l[b]]`` and the right ones ``order_r[b, :count_r[b]]``,
    ordered by column."""
    score = np.zeros(sim.shape)
    cost = np.empty((order_l.shape[1] + 1, order_r.shape[1] + 1))
    move = np.empty(cost.shape, np.int8)  # 0 match, 1 skip left, 2 skip right
    for b in range(height.shape[0]):
        nl, nr = count_l[b], count_r[b]
        if nl == 0 or nr == 0:
            continue
        bl, br = order_l[b], order_r[b]
        for i in range(nl + 1):
            cost[i, 0] = i * occlusion_cost
            move[i, 0] = 1
        for j in range(nr + 1):
            cost[0, j] = j * occlusion_cost
            move[0, j] = 2
        for i in range(1, nl + 1):
            for j in range(1, nr + 1):
                best = cost[i - 1, j] + occlusion_cost
                m = 1
                c = cost[i, j - 1] + occlusion_cost
                if c < best:
                    best = c
                    m = 2
                s = sim[bl[i - 1], br[j - 1]]
                if not np.isnan(s):
                    c = cost[i - 1, j - 1] + 1.0 - s
                    if c <= best:
                        best = c
                        m = 0
                cost[i, j] = best
                move[i, j] = m
        i, j = nl, nr
        while i > 0 and j > 0:
            m = move[i, j]
            if m == 0:
                score[bl[i - 1], br[j - 1]] += height[b] * sim[bl[i - 1], br[j - 1]]
                i -= 1
                j -= 1
            elif m == 1:
                i -= 1
            else:
                j -= 1
    return score


@njit(cache=True)
def _consolidate(li, ri, lu, lslope, ltop, lbottom, ru, rslope, rtop, rbottom):
    """Greedy one-to-one, order-preserving selection of ranked pairs (step 3 of match_segments)."""
    n = li.size
    keep = np.zeros(n, np.bool_)
    used_l = np.zeros(lu.size, np.bool_)
    used_r = np.zeros(ru.size, np.bool_)
    for p in range(n):
        i, j = li[p], ri[p]
        if used_l[i] or used_r[j]:
            continue
        top_p = max(ltop[i], rtop[j])
        bottom_p = min(lbottom[i], rbottom[j])
        ok = True
        for q in range(p):
            if not keep[q]:
                continue
            k, m = li[q], ri[q]
            top = max(top_p, max(ltop[k], rtop[m]))
            bottom = min(bottom_p, min(lbottom[k], rbottom[m]))
            if bottom <= top:
                continue
            v = 0.5 * (top + bottom)
            du_l = (lu[i] + lslope[i] * (v - 0.5 * (ltop[i] + lbottom[i]))) - (
                lu[k] + lslope[k] * (v - 0.5 * (ltop[k] + lbottom[k]))
            )
            du_r = (ru[j] + rslope[j] * (v - 0.5 * (rtop[j] + rbottom[j]))) - (
                ru[m] + rslope[m] * (v - 0.5 * (rtop[m] + rbottom[m]))
            )
            if du_l * du_r < 0:
                ok = False
                break
        if ok:
            keep[p] = True
            used_l[i] = True
            used_r[j] = True
    return keep
