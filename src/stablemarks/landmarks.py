"""Landmark modeling on known planes and the selection of stable landmarks (paper Sec 3–4).

For a fitted planar region with a free edge in view:

1. :func:`search_boundary` — Sec 3.2: in the search window around the predicted edge, the boundary
   pixels of the region (the outermost region pixel of each row) are compared with every candidate
   column; the column of least variance is the boundary, that variance its uncertainty. A boundary
   inside the outermost member segment is moved to it. Done in both images, triangulated and
   constrained to the fitted plane (Eqs 12–14): ``P_b, Σ_Pb``.
2. :func:`model_features` — each member segment pair is triangulated (Sec 2.3.1), constrained to the
   plane (Eqs 12–14) and expressed relative to the boundary, ``d_p = (P_f − P_b)·t``; its map position is
   ``P = P_M + d_p t`` (Eq 15, ``t`` the wall's direction from the matched free edge) with the rank-1
   covariance ``Σ_P = (σ_b² + σ_f²) t tᵀ`` (Eq 17): zero across the wall.
3. :func:`select` — Sec 4: a feature whose 3σ interval along the wall touches the 3σ region of a visible
   free edge, ``|d_p| <= 3 (σ_b + σ_f)``, is near the boundary (the paper's "3σ boundary region" made
   exact; ``boundary_rule="combined"`` gives DESIGN.md §4's ``3·sqrt(σ_b² + σ_f²)``); a pair with length
   similarity ``ℓ_s`` (Eq 18) below the threshold is unstable. Every rejection carries its reason.

All positions are in the map frame [m]; the landmark state handed to the filter is ``s = d_p`` along the
wall (DESIGN.md §4), and landmarks modelled from one boundary share its variance ``σ_b²``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numba import njit

from .errors import InputError, expected
from .geometry import StereoCamera
from .maps import Map, nearest_crossing, sight_blocked
from .planes import PlaneConfig, PlaneFit, _pairwise_sum, fuse_one, median, plane_members

REASON_NEAR_BOUNDARY = "near boundary"
REASON_LENGTH = "low length similarity"
REASON_OUTSIDE = "outside the plane"
REASON_CONTRAST = "low contrast"
REASON_OFF_WALL = "off the wall"
REASON_HEIGHT = "beyond the wall's height"
REASON_FAR = "too far"
REASON_OBLIQUE = "too oblique"
REASON_BESIDE_NEARER = "beside something nearer"
REASON_SCATTER = "wall's lines scatter about its fit"
REASON_BESIDE_LINE = "beside another line"


@dataclass(frozen=True)
class LandmarkConfig:
    """Selection and modeling thresholds (paper Sec 3.2 and 4)."""

    def __post_init__(self) -> None:
        if self.boundary_rule not in ("disjoint", "combined"):
            raise InputError(expected("'disjoint' or 'combined'", self.boundary_rule, where="landmarks.boundary_rule"))
        if not 0.0 <= self.min_length_similarity <= 1.0:
            raise InputError(expected("a number in [0, 1]", self.min_length_similarity,
                                      where="landmarks.min_length_similarity"))
        if self.filter_boundary_sigma not in ("measured", "model"):
            raise InputError(expected("'measured' or 'model'", self.filter_boundary_sigma,
                                      where="landmarks.filter_boundary_sigma"))
        for name in ("off_wall_sigma", "off_wall_floor_px", "row_sigma_px", "max_range", "max_incidence_deg",
                     "boundary_gate_sigma", "fit_gate_chi2", "nearer_fraction", "nearer_fit_sigma"):
            v = getattr(self, name)
            if v is None and name == "nearer_fit_sigma":
                continue
            if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v > 0):
                raise InputError(expected("a positive number", v, where=f"landmarks.{name}"))
        v = self.off_wall_min_lines
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise InputError(expected("a whole number >= 0", v, where="landmarks.off_wall_min_lines"))
        v = self.scatter_px
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v > 0)):
            raise InputError(expected("a positive number of pixels, or null (noise.sigma_img)", v,
                                      where="landmarks.scatter_px"))
        v = self.min_line_gap_px
        if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
            raise InputError(expected("a number of pixels >= 0 (0: off)", v, where="landmarks.min_line_gap_px"))
        if not (np.isfinite(self.min_contrast) and self.min_contrast >= 0):
            raise InputError(expected("a number of gray levels >= 0", self.min_contrast,
                                      where="landmarks.min_contrast"))

    boundary_sigma: float = 3.0
    """Width of the unstable boundary region and of the feature's interval, in σ (Sec 4)."""
    boundary_rule: str = "disjoint"
    """How the near-boundary test combines the boundary's and the feature's σ along the wall (Sec 4):
    ``disjoint`` rejects a feature whose ``k``σ interval touches the boundary's ``k``σ region,
    ``|d_p| <= k (σ_b + σ_f)``; ``combined`` rejects ``|d_p| <= k sqrt(σ_b² + σ_f²)`` (DESIGN.md §4).
    With Table 1's own figures (partition 2: d_p = 109.4 mm, σ = 35.0 mm) only ``disjoint`` reproduces the
    paper's rejection."""
    min_length_similarity: float = 0.7
    """Reject pairs with ``ℓ_s`` (Eq 18) below this (Sec 4)."""
    filter_boundary_sigma: str = "model"
    """Which σ of the boundary enters the filter with the landmarks modelled from it: ``measured`` (the
    minimum-variance column's spread and the image noise, DESIGN §4) or ``model`` (that plus the SAD window
    allowance ``w²/12`` that the near-boundary rule uses, which reproduces Table 1's σ but is several times
    the actual error where the region's border is sharp, making the filter under-confident)."""
    min_contrast: float = 30.0
    """Reject features whose brightness step across the line (the left segment's mean ``|Sobel_x| / 4``) is
    below this many gray levels. Beyond the paper: a textured wall (wood grain, fabric, speckled paint) yields
    many short, weak vertical edges that are stable in place but alike and easily confused; painted lines,
    frames and panel edges step by tens of gray levels. 0 keeps every edge."""
    search_sigma: float = 3.0
    """Half-width of the boundary search window in σ of the predicted edge column (Eq 6)."""
    min_boundary_rows: int = 15
    """Fewer rows reaching the search window than this: no boundary found in that image."""
    fallback_sigma_px: float = 3.0
    """Column σ used for the right image when its boundary cannot be searched."""
    row_outlier_mad: float = 3.0
    """Rows whose boundary column is farther than this many robust σ (1.4826·MAD) from the median are not
    the plane's edge (e.g. floor pixels at the wall's foot that share its depth) and are left out."""
    boundary_window_px: float | None = None
    """Width [px] of the area-matching window. A SAD region's border is only known to within the window
    (block matching spreads a depth edge over it), so the boundary gets the variance of a uniform
    distribution over that width, ``w²/12``, shared by both images. ``None``: the SAD block size."""
    off_wall_sigma: float = 3.0
    """A candidate is on its wall only if its triangulated position agrees with the fitted plane (the
    innovation of the point-on-plane update, Eqs 12–14) within this many σ; farther is "off the wall" (a
    pole or a box corner standing in front of it). The smallest offset this resolves at range ``Z`` seen
    frontally is about ``off_wall_sigma · sqrt(2) σ_line · Z² / (f b)``, σ_line the lines' column noise:
    the model's ``noise.sigma_img`` (0.28 m at 4 m and 0.64 m at 6 m with 0.25 px, f = 500 px, b = 0.12 m;
    1.27 m at 6 m with the paper's 0.5 px), or what the frame's own lines show (``off_wall_min_lines``)."""
    off_wall_min_lines: int = 10
    """With at least this many candidate lines in a frame, the off-wall test takes the lines' column noise from
    the lines themselves (:func:`line_noise_scale`): 1.4826 × the median of ``|G| / σ_G`` over all of them (the
    offset from their fitted walls in units of what ``noise.sigma_img`` predicts; the median ignores the lines
    of clutter as long as they are fewer than half), when that is below 1. The model's σ_img is kept wide for
    the filter, which must also absorb errors that are not line noise; measured on the simulator's lines it is
    5–10 times their scatter, and a desk's edge 0.2 m in front of a wall at 6.5 m was 1–2.4 σ off its wall with
    it and 4–12 σ with the lines' own scatter. The data can only make the test stricter than the model, never
    looser. 0: the model's σ_img alone (the paper's test)."""
    off_wall_floor_px: float = 0.05
    """The least column noise [px] the off-wall test assumes of a line, however clean the frame's lines look:
    a single line errs by its own texture and by sub-pixel interpolation's pull towards whole pixels, which the
    spread of many lines understates (measured on the simulator's walls: lines 0.01–0.07 px RMS from their true
    edges, by wall; a painted bar 0.2 m from a clean wall's edge was 4 σ off its wall with the median spread of
    its frame's lines alone)."""
    row_sigma_px: float = 2.0
    """σ of a segment's end row [px], for the height test: a candidate's ends must lie within the wall's
    mapped ``z`` range widened by ``off_wall_sigma`` σ of their height (rows and depth); beyond it the line
    belongs to something else (a pole standing in front of a whiteboard reaches the floor)."""
    max_range: float = 12.0
    """Candidates farther than this from the camera [m] are not entered ("too far"). Measured
    (``python benchmarks/entry_limits.py loop corridor --frames 200``, 3953 candidates): below 60° of
    incidence the along-wall error stays at 6–19 mm RMS from 0 to 11 m; range alone is not what hurts."""
    max_incidence_deg: float = 60.0
    """Candidates whose viewing ray meets the wall more than this far from its normal [deg] are not entered
    ("too oblique"): a wall seen at a grazing angle stretches the SAD window over a wide stretch of wall and
    half-hides lines behind nearer walls. Measured as above: 5–9 mm RMS along the wall below 60°, 63 mm at
    60–70°, 149 mm at 70–80° (up to 0.54 m, several σ: the errors behind the loop's drifting landmarks). The
    same limit keeps a landmark already in the filter from being associated while its wall is seen more
    obliquely (:meth:`~stablemarks.estimation.JointEKF.visible`), and a free edge seen more obliquely from the
    mean pose from being searched at all: its boundary is a line on the wall like the others, and every landmark
    placed from it would carry its error."""
    boundary_gate_sigma: float = 3.0
    """A found boundary farther along the wall from the map's free edge than this many σ (its own σ and the
    pose's, projected on the wall) disagrees with the map: nothing is modelled from it in that frame. The same
    gate holds the distance between a wall's two ends, when both are found, to the map's length (their own σ
    only: it does not depend on the pose); beyond it the end that agrees less with the map is not used."""
    fit_gate_chi2: float = 13.8
    """A fitted wall line ``(a, b)`` (offset and slope from the map's wall, seen through the belief) must agree
    with the map given the pose covariance, the fit's own and the map's (:attr:`Map.accuracy`, e.g. of walls
    extracted from an occupancy grid): Mahalanobis² at most this (χ²₂, 0.999). A
    line that does not is another surface caught in a wide band (a wall behind a free-standing screen when
    the heading is uncertain), bent and shifted far beyond its σ: nothing is modelled from it in that frame."""
    nearer_fraction: float = 0.5
    """A candidate is at the silhouette of something standing in front of its wall when, on one side of the line
    and on at least this fraction of its rows that hold a disparity there, the disparity image is nearer than the
    wall's band (:func:`beside_nearer`): its left line may be the nearer object's edge, matched with a line of
    the wall in the other image (the corridor: a poster board's edge, 0.7 px from a line of the poster behind
    it, taken for it), or a line of the wall that the nearer object half hides. Such a line is rejected ("beside
    something nearer"); a T-junction is not a stable landmark. The same reason rejects a line within
    ``boundary_sigma`` σ (the pose's, through Eq 3, and the line noise) of a column where the end of another wall
    of the map is seen against this one while standing too little in front of it for the disparity to show
    (:func:`nearer_silhouettes`: the hall's screens 1 m in front of its walls at 10 m, 0.6 px). Measured with
    ``stablemarks eval`` (20 trials, December 2026): corridor selection precision 0.91 → 1.00 (pose NEES 1.8 →
    2.8), hall 0.90 → 0.97 (recall 0.74 → 0.73), room's recall 0.97 → 0.94; lab unchanged, office's 0.89 too.
    The image test also looks beyond a found boundary (:func:`occluded_boundary`): something nearer there hides
    the wall's end, and the border is not used (office: precision 0.89 → 0.90, pose NEES 2.61 → 2.02, the
    other scenarios unchanged). 1 turns all three tests off."""
    nearer_fit_sigma: float | None = 5.0
    """The same question asked of the wall as fitted in this frame rather than of its predicted band: a candidate
    is "beside something nearer" when, on one side of its left line (half a window to a window beyond it, over its
    rows), the median disparity is nearer than the fitted wall's by more than this many standard errors
    (:func:`nearer_than_fit`; the error of a median of the rows, one independent row per SAD window, from the
    larger of ``planes.disparity_noise_px`` and the rows' own spread, and the fitted wall's covariance). The band's
    test needs ``gate`` σ of the pose plus 1 px; this one resolves a few tenths of a pixel when the line is long
    (``docs/uncertainty.md``, "Something nearer than the fitted wall", for what it scores on the built-in scenes
    and what it cannot resolve: a desk's corner 0.2 m in front of a wall at 6 m seen at 35°, whose side face is a
    few pixels wide there, stays in). With ``stablemarks eval`` (5 trials):
    office precision 0.89 → 0.92, storeroom landmark NEES 0.63 → 0.14 and recall 0.48 → 0.52, lab, room and
    corridor unchanged. None turns it off."""
    min_line_gap_px: float = 0.0
    """A candidate with another line of the left image between 1 px and this far from it [px] is not entered
    ("beside another line"). The detector (Sobel_x, non-maximum suppression along the row) places each of two
    edges 3 px apart 0.15 px toward the other, frame after frame, and from 5 px apart within 0.05 px
    (``tests/test_segments.py``); such a bias is no noise the filter can average away (the office's whiteboard:
    a 2 cm dark line's two edges, 0.15 px inside it in 41 frames out of 41, 2.5 times a measured σ_img of
    0.06 px). Lines under 1 px apart are the same edge in pieces. 0: off."""
    scatter_px: float | None = None
    """The column noise [px] a wall's lines may show about its fitted line before the wall is not modelled in a
    frame (:func:`wall_line_scatter`, "the fit mixes the wall with something in front of it"); None:
    ``noise.sigma_img``. The test guards against fits that take in clutter, whose lines scatter by many times
    the line noise, so its tolerance is what lines on one wall can scatter by, not the filter's noise: with
    ``noise.sigma_img`` set to the lines' usual error (0.06 px) the same test refused walls whose lines scatter
    by 0.1 px (the storeroom's north wall after a blind stretch, 1.7–5 times "too far")."""
    min_edge_step_sigma: float = 3.0
    """A free edge is searched only where the map puts something at a different depth just beyond it: the
    disparity step the map predicts across the edge must reach this many σ of the disparity noise
    (``planes.disparity_noise_px``). Without a step the planar region runs on over the background (a
    poster board a few centimetres in front of a perpendicular wall) and its end is not the edge."""


@dataclass(frozen=True)
class Boundary:
    """A plane's free edge found in the images (Sec 3.2), constrained to the fitted plane.

    ``u`` (2,) columns in the left and right image [px], ``sigma_u`` (2,) their σ [px], ``P`` (2,) the
    constrained boundary position ``P_b`` in the map frame [m], ``cov`` (2, 2) ``Σ_Pb`` [m²], ``sigma_along``
    its σ along the wall [m] (with the SAD window allowance, for the selection rule), ``sigma_along_measured``
    the same from the rows' spread and the image noise alone (computed only when
    ``landmarks.filter_boundary_sigma`` is ``measured``, else NaN); ``snapped`` when moved to the outermost member
    segment; ``rows`` the number of image rows that entered the left search; ``inward`` (2,) the wall's unit
    direction from this edge into the wall. ``cov_uv`` (2, 2) the covariance of ``u`` [px²] (with the SAD window
    allowance, shared by both images) and ``cov_uv_measured`` without it (NaN unless ``measured``).
    """

    plane_id: str
    edge: str
    u: np.ndarray
    sigma_u: np.ndarray
    P: np.ndarray
    cov: np.ndarray
    sigma_along: float
    snapped: bool
    rows: int
    inward: np.ndarray
    sigma_along_measured: float = np.nan
    cov_uv: np.ndarray | None = field(default=None, repr=False)
    cov_uv_measured: np.ndarray | None = field(default=None, repr=False)


@dataclass(frozen=True)
class Candidate:
    """A feature on a reference plane, modelled relative to the plane's free edge (Table 1's rows).

    Attributes
    ----------
    plane_id, plane_label : the wall.
    index : 1-based rank by distance from the free edge (Table 1's ``index``).
    pair : index of the segment pair in the frame's pairs.
    edge : the free edge the feature is measured from (``"p1"`` / ``"p2"``).
    s : ``d_p``, distance along the wall from that edge [m] (the filter's landmark state).
    sigma_b, sigma_f : along-wall σ of the boundary and of the feature [m].
    P : (2,) position in the map (Eq 15) [m]; ``cov`` (2, 2) its rank-1 covariance (Eq 17) [m²].
    z_low, z_high : heights of the segment's ends [m]; ``length`` = z_high − z_low [m].
    length_similarity : ``ℓ_s`` (Eq 18).
    selected, reason : the selection decision and, when rejected, why (Sec 4).
    P_observed, cov_observed : the plane-constrained triangulated point (Eqs 12–14), map frame.
    contrast : brightness step across the line in the left image [gray levels] (``inf`` when unknown).
    sigma_b_measured : the boundary's σ along the wall without the SAD window allowance [m] (see
        :attr:`LandmarkConfig.filter_boundary_sigma`).
    wall_offset, sigma_wall_offset : the triangulated point's offset from the fitted plane along its normal
        before the plane constraint (Eq 12's ``G``) and its σ (image noise and the fit) [m];
        ``sigma_wall_fit`` the fit's part of that σ [m].
    height_margin : how far [m] the segment's ends may reach beyond the wall's mapped height (``k`` σ of the
        heights from the rows and the depth).
    range : distance from the left optical centre [m]; ``incidence`` the angle between the viewing ray and
        the wall's normal [rad].
    shared_jacobian, shared_cov, sigma_own : the error model of ``s`` that the filter enters (DESIGN §4):
        ``s`` is a function of what all features of the plane share — the fitted line ``(a, b)`` and the
        boundary's columns ``(u_l, u_r)``, with covariance ``shared_cov`` (4, 4) — and of the feature's own
        columns. ``shared_jacobian`` (4,) is ``∂s/∂(a, b, u_bl, u_br)``, ``sigma_own`` [m] the σ of ``s`` from
        the feature's own columns. Features of one boundary then have ``Σ = J Σ_shared Jᵀ + diag(σ_own²)``:
        the line's slope moves them all, in proportion to their distance from the edge (not captured by
        ``σ_b² 11ᵀ + diag(σ_f²)``, which treats the fit's error as independent per feature).
    """

    plane_id: str
    plane_label: str
    index: int
    pair: int
    edge: str
    s: float
    sigma_b: float
    sigma_f: float
    P: np.ndarray
    cov: np.ndarray
    z_low: float
    z_high: float
    length_similarity: float
    u_left: float
    u_right: float
    v_top: float
    v_bottom: float
    selected: bool = False
    reason: str = ""
    P_observed: np.ndarray = field(default_factory=lambda: np.zeros(2), repr=False)
    cov_observed: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)), repr=False)
    contrast: float = np.inf
    sigma_b_measured: float = np.nan
    wall_offset: float = 0.0
    sigma_wall_offset: float = np.inf
    sigma_wall_fit: float = 0.0
    height_margin: float = np.inf
    range: float = 0.0
    incidence: float = 0.0
    shared_jacobian: np.ndarray | None = field(default=None, repr=False)
    shared_cov: np.ndarray | None = field(default=None, repr=False)
    sigma_own: float = np.nan

    @property
    def sigma_s(self) -> float:
        """σ of ``s`` along the wall: ``sqrt(σ_b² + σ_f²)`` (Eq 17) [m]."""
        return float(np.hypot(self.sigma_b, self.sigma_f))

    @property
    def sigma_wall_line(self) -> float:
        """The lines' part of :attr:`sigma_wall_offset` [m]: without the fit's (``sigma_wall_fit``)."""
        return math.sqrt(max(self.sigma_wall_offset**2 - self.sigma_wall_fit**2, 0.0))

    @property
    def sigma_relative(self) -> float:
        """σ of ``s`` from the joint error model (``shared_jacobian``; :attr:`sigma_s` without it) [m]."""
        if self.shared_jacobian is None:
            return self.sigma_s
        j = self.shared_jacobian
        return float(np.sqrt(j @ self.shared_cov @ j + self.sigma_own**2))

    @property
    def length(self) -> float:
        return self.z_high - self.z_low


def _boundary_columns(region: np.ndarray, lo: float, hi: float, outward: int, max_hole: int = 2
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Per row, where the region ends going ``outward`` (−1: left, +1: right) through columns ``[lo, hi]``.

    The region's run that starts nearest the window's inner side is followed outward (holes of up to
    ``max_hole`` px closed: pixels the disparity checks left out) to its end: beyond a gap the region may go
    on over a wall in line with this one, which is not this wall's edge. Returns rows and their boundary
    columns; rows whose region does not reach into the window are left out, and so are rows whose run goes
    through it (it ends beyond the window). One pass over each row of the window (:func:`_block_row_ends`, the
    region being its own block).
    """
    return _block_boundary_columns(region, 0, 0, region.shape[1], lo, hi, outward, max_hole)


def _block_boundary_columns(block: np.ndarray, v0: int, u0: int, W: int, lo: float, hi: float, outward: int,
                            max_hole: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_boundary_columns` of a region ``W`` columns wide that holds no pixel outside ``block`` (h, w), its
    rows ``v0 …`` and columns ``u0 …``: the same rows and columns, walking only the block's rows of the window
    (rows outside it have no end). Why: the search reads a few dozen columns of a plane's rows, the full-image
    masks cost an (H, W) allocation and a walk over every image row."""
    c0 = math.floor(min(max(lo, 0), W - 1))
    c1 = math.ceil(min(max(hi, 0), W - 1))
    if c1 < c0:
        return np.zeros(0, int), np.zeros(0)
    return _block_row_ends(np.ascontiguousarray(block, dtype=np.bool_), int(v0), int(u0), c0, c1, int(outward),
                           int(max_hole))


@njit(cache=True)
def _block_row_ends(block, v0, u0, c0, c1, outward, max_hole):  # pragma: no cover - numba
    """Per row of a region that is ``block`` (h, w) at rows ``v0…``, columns ``u0…`` and False elsewhere, read in
    place, where it ends in the window of columns ``c0…c1``: walking from the window's inner side (``c1`` when
    ``outward`` < 0, else ``c0``), the first region pixel starts the run; a hole of at most ``max_hole`` px
    followed by a region pixel is crossed; the run ends before any other hole, also one that reaches the window's
    outer side. Rows with no region pixel in the window, or whose run reaches the outer side, have no end.
    Returns (rows, columns as float) in image coordinates."""
    h, w = block.shape
    n = c1 - c0 + 1
    first = c1 if outward < 0 else c0  # the image column of position j from the inner side: first + step·j
    step = -1 if outward < 0 else 1
    rows = np.empty(h, dtype=np.int64)
    cols = np.empty(h, dtype=np.float64)
    k = 0
    for i in range(h):
        start = n
        for j in range(n):
            c = first + step * j - u0
            if 0 <= c < w and block[i, c]:
                start = j
                break
        last = -1  # the run's last pixel, once a hole not crossed ends it
        j = start + 1
        while j < n:
            c = first + step * j - u0
            if 0 <= c < w and block[i, c]:
                j += 1
                continue
            q = j + 1  # the next region pixel after the hole that starts at j (not looked for beyond the widest
            while q < n and q - j <= max_hole:  # hole crossed: the run ends there whatever follows)
                c = first + step * q - u0
                if 0 <= c < w and block[i, c]:
                    break
                q += 1
            if q < n and q - j <= max_hole:
                j = q
            else:
                last = j - 1
                break
        if last >= 0:
            rows[k] = v0 + i
            cols[k] = float(first + step * last)
            k += 1
    return rows[:k].copy(), cols[:k].copy()


def robust_rows(cols: np.ndarray, k: float) -> np.ndarray:
    """Mask of boundary columns within ``k`` robust σ (1.4826·MAD, at least 1 px) of their median."""
    if len(cols) == 0:
        return np.zeros(0, dtype=bool)
    med = median(cols)
    scale = max(1.0, 1.4826 * median(np.abs(cols - med)))
    return np.abs(cols - med) <= k * scale


def minimum_variance_column(cols: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """Sec 3.2: for every candidate column ``m`` in ``[lo, hi]`` take the variance of the boundary
    pixels about ``m``, ``mean((b − m)²)``; return the column of least variance and that variance [px²].

    The minimum of ``mean((b − m)²)`` over ``m`` is at the mean of ``b``; the search over integer columns
    is kept (it respects the window) and refined to the mean when the mean lies inside it.
    """
    m = float(cols.mean())
    if not lo <= m <= hi:
        cand = np.arange(np.ceil(lo), np.floor(hi) + 1.0)
        if len(cand) == 0:
            cand = np.array([0.5 * (lo + hi)])
        var = ((cols[None, :] - cand[:, None]) ** 2).mean(axis=1)
        m = float(cand[int(np.argmin(var))])
    return m, float(((cols - m) ** 2).mean())


@njit(cache=True)
def _left_end_column(block, v0, u0, c0, c1, outward, max_hole, k, lo, hi):  # pragma: no cover - numba
    """:func:`search_boundary`'s left image: :func:`_block_row_ends` of the window's columns ``c0 … c1``, then
    :func:`_robust_minimum_variance` of the rows' columns (``k``, ``lo``, ``hi``), in one call; the row ends looked
    for from the window's outer side when any hole is bridged (:func:`_block_row_ends_back`)."""
    if max_hole >= c1 - c0 - 1:
        _, cols = _block_row_ends_back(block, v0, u0, c0, c1, outward)
    else:
        _, cols = _block_row_ends(block, v0, u0, c0, c1, outward, max_hole)
    return _robust_minimum_variance(cols, k, lo, hi)


@njit(cache=True)
def _block_row_ends_back(block, v0, u0, c0, c1, outward):  # pragma: no cover - numba
    """:func:`_block_row_ends` when any hole is bridged (``max_hole >= n − 2``, ``n = c1 − c0 + 1``: from any hole its
    walk looks to the window's outer side): a row's run ends at the last region pixel of the window, none when that
    is the outer side's own or there is none — looked for from the outer side, the same rows and columns."""
    h, w = block.shape
    n = c1 - c0 + 1
    first = c1 if outward < 0 else c0
    step = -1 if outward < 0 else 1
    rows = np.empty(h, dtype=np.int64)
    cols = np.empty(h, dtype=np.float64)
    k = 0
    for i in range(h):
        last = -1
        for j in range(n - 1, -1, -1):
            c = first + step * j - u0
            if 0 <= c < w and block[i, c]:
                if j < n - 1:
                    last = j
                break
        if last >= 0:
            rows[k] = v0 + i
            cols[k] = float(first + step * last)
            k += 1
    return rows[:k].copy(), cols[:k].copy()


@njit(cache=True)
def _right_end_column(sub, c0, v0, u0, table, gate, row_margin, w0, w1, outward, max_hole, k, lo,
                      hi):  # pragma: no cover - numba
    """:func:`search_boundary`'s right image: :func:`_right_row_ends` of the window's columns ``w0 … w1``, then
    :func:`_robust_minimum_variance` of the rows' columns (``k``, ``lo``, ``hi``), in one call. The rows whose
    band test passes on its rows' part whatever the column (between the lowest top and the highest bottom the table
    interpolates, a 1e-6 px margin for the interpolation's rounding) test the disparity only
    (:func:`_right_row_ends_in`): the same pixels, the same walk."""
    K = table.shape[0]
    top, bottom = table[0, 4], table[0, 6]
    for j in range(K):
        top = max(top, table[j, 4])
        bottom = min(bottom, table[j, 6])
    _, cols = _right_row_ends_in(sub, c0, v0, u0, table, gate, row_margin, w0, w1, outward, max_hole,
                                 top - row_margin + 1e-6, bottom + row_margin - 1e-6)
    return _robust_minimum_variance(cols, k, lo, hi)


@njit(cache=True)
def _sorted_median(x):  # pragma: no cover - numba
    """:func:`~stablemarks.planes.median` of a 1-D array (at least one number) by sorting a copy: the same element, or
    the same two averaged."""
    p = np.sort(x)
    k = len(p) // 2
    return p[k] if len(p) % 2 else (p[k - 1] + p[k]) / 2


@njit(cache=True)
def _robust_minimum_variance(cols, k, lo, hi):  # pragma: no cover - numba
    """:func:`robust_rows` of the boundary columns ``cols`` (``k`` robust σ), then :func:`minimum_variance_column`
    of those kept in ``[lo, hi]``: ``(number kept, column, variance)``, ``(0, NaN, NaN)`` when none. The same
    medians, means (:func:`_pairwise_sum`: NumPy's summation order) and first least variance, in one call: the
    two functions' NumPy calls cost ~20 µs per image and edge."""
    n = cols.shape[0]
    if n == 0:
        return 0, np.nan, np.nan
    med = _sorted_median(cols)
    dev = np.abs(cols - med)
    scale = max(1.0, 1.4826 * _sorted_median(dev))
    kept = cols[dev <= k * scale]
    m = kept.shape[0]
    if m == 0:
        return 0, np.nan, np.nan
    mean = _pairwise_sum(kept, 0, m) / m
    if not lo <= mean <= hi:
        c0, c1 = np.ceil(lo), np.floor(hi) + 1.0  # the candidates np.arange(c0, c1): whole numbers
        n_cand = int(c1 - c0) if c1 > c0 else 0
        sq = np.empty(m)
        best_var = np.inf
        if n_cand == 0:
            mean = 0.5 * (lo + hi)
        for i in range(n_cand):
            cand = c0 + i
            for q in range(m):
                sq[q] = (kept[q] - cand) * (kept[q] - cand)
            v = _pairwise_sum(sq, 0, m) / m
            if v < best_var or i == 0:
                best_var, mean = v, cand
    sq = (kept - mean) * (kept - mean)
    return m, mean, _pairwise_sum(sq, 0, m) / m


def right_region(prediction, disparity_right: np.ndarray, row_margin: float = 0.0,
                 columns: tuple[int, int] | None = None) -> np.ndarray:
    """The plane's pixels in the right image: right-reference disparities inside the plane's band.

    A right pixel ``x`` with disparity ``d`` sees the left column ``x + d``, where the band is tested.
    ``columns`` (first, last) limits the work to a window of right-image columns; the mask is (H, W).
    """
    out = np.zeros(disparity_right.shape, dtype=bool)
    v0, c0, block = _right_block(prediction, disparity_right, row_margin, columns)
    out[v0 : v0 + block.shape[0], c0 : c0 + block.shape[1]] = block
    return out


def _right_block(prediction, disparity_right: np.ndarray, row_margin: float = 0.0,
                 columns: tuple[int, int] | None = None) -> tuple[int, int, np.ndarray]:
    """:func:`right_region` inside its bounding block: ``(v0, c0, block)``, ``block`` (h, w) the mask's rows
    ``v0 …`` and columns ``c0 …`` (the rows the plane reaches, the ``columns`` asked for); the mask holds no pixel
    outside it (an empty block when none)."""
    H, W = disparity_right.shape
    c0, c1 = (0, W - 1) if columns is None else (max(0, int(columns[0])), min(W - 1, int(columns[1])))
    if c1 < c0:
        return 0, 0, np.zeros((0, 0), dtype=bool)
    v0 = max(0, int(np.floor(prediction.v_top.min() - row_margin)))
    v1 = min(H - 1, int(np.ceil(prediction.v_bottom.max() + row_margin)))
    if v1 < v0:
        return 0, 0, np.zeros((0, 0), dtype=bool)
    return v0, c0, _right_band(disparity_right[v0 : v1 + 1, c0 : c1 + 1], c0, v0, int(prediction.columns[0]),
                               prediction.band_table, float(prediction.gate), float(row_margin))


def _right_box(prediction, disparity_right: np.ndarray, row_margin: float = 0.0,
               columns: tuple[int, int] | None = None) -> tuple[np.ndarray, int, int]:
    """:func:`_right_block`'s box without its mask: ``(sub, v0, c0)``, ``sub`` the right disparities of the block's
    rows ``v0 …`` and columns ``c0 …`` (an empty (0, 0) box where :func:`_right_block` gives an empty block)."""
    H, W = disparity_right.shape
    c0, c1 = (0, W - 1) if columns is None else (max(0, int(columns[0])), min(W - 1, int(columns[1])))
    if c1 < c0:
        return disparity_right[:0, :0], 0, 0
    top, bottom = prediction.rows_reached  # v_top.min(), v_bottom.max(), made once per prediction
    v0 = max(0, math.floor(top - row_margin))
    v1 = min(H - 1, math.ceil(bottom + row_margin))
    if v1 < v0:
        return disparity_right[:0, :0], 0, 0
    return disparity_right[v0 : v1 + 1, c0 : c1 + 1], v0, c0


def _right_boundary_columns(prediction, sub: np.ndarray, v0: int, c0: int, W: int, lo: float, hi: float,
                            outward: int, max_hole: int, row_margin: float) -> tuple[np.ndarray, np.ndarray]:
    """``_block_boundary_columns(block, v0, c0, W, lo, hi, outward, max_hole)`` of the right region's block
    ``_right_block`` makes of the box ``sub`` (:func:`_right_box`), without making it: each pixel's band test
    (:func:`_right_band`'s, the same arithmetic) done where the row walk reads it (:func:`_right_row_ends`); the
    walk stops at each row's end, so the pixels beyond it (about half a search window) are never tested."""
    lo_c = math.floor(min(max(lo, 0), W - 1))
    hi_c = math.ceil(min(max(hi, 0), W - 1))
    if hi_c < lo_c:
        return np.zeros(0, int), np.zeros(0)
    return _right_row_ends(sub, int(c0), int(v0), int(prediction.columns[0]), prediction.band_table,
                           float(prediction.gate), float(row_margin), lo_c, hi_c, int(outward), int(max_hole))


@njit(cache=True, inline="always")
def _right_pixel(sub, i, k, c0, v0, u0, table, gate, row_margin):  # pragma: no cover - numba
    """:func:`_right_band`'s value at ``(i, k)`` of the box ``sub``: the same tests and interpolation."""
    K = table.shape[0]
    u_last = u0 + K - 1
    v = float(v0 + i)
    disp = float(sub[i, k])
    u = float(c0 + k) + disp
    if not (u >= u0 and u <= u_last):  # also NaN
        return False
    j = int(u - u0)
    if j == K - 1:
        return (abs(disp - table[j, 0]) <= gate * table[j, 2] and v >= table[j, 4] - row_margin
                and v <= table[j, 6] + row_margin)
    frac = u - float(u0 + j)
    dp = table[j, 1] * frac + table[j, 0]
    sp = table[j, 3] * frac + table[j, 2]
    if not abs(disp - dp) <= gate * sp:
        return False
    vt = table[j, 5] * frac + table[j, 4]
    vb = table[j, 7] * frac + table[j, 6]
    return v >= vt - row_margin and v <= vb + row_margin


@njit(cache=True, inline="always")
def _right_pixel_in(sub, i, k, c0, v0, u0, table, gate, row_margin, rows_sure):  # pragma: no cover - numba
    """:func:`_right_pixel`, its rows' part left out when ``rows_sure`` (the row passes it at every column)."""
    if not rows_sure:
        return _right_pixel(sub, i, k, c0, v0, u0, table, gate, row_margin)
    K = table.shape[0]
    u_last = u0 + K - 1
    disp = float(sub[i, k])
    u = float(c0 + k) + disp
    if not (u >= u0 and u <= u_last):  # also NaN
        return False
    j = int(u - u0)
    if j == K - 1:
        return abs(disp - table[j, 0]) <= gate * table[j, 2]
    frac = u - float(u0 + j)
    dp = table[j, 1] * frac + table[j, 0]
    sp = table[j, 3] * frac + table[j, 2]
    return abs(disp - dp) <= gate * sp


@njit(cache=True)
def _right_row_ends_in(sub, c0, v0, u0, table, gate, row_margin, w0, w1, outward, max_hole, v_sure_lo,
                       v_sure_hi):  # pragma: no cover - numba
    """:func:`_right_row_ends` with the rows ``v_sure_lo <= v <= v_sure_hi`` tested on their disparity only
    (:func:`_right_pixel_in`): the same rows and columns. When any hole is bridged (``max_hole >= n − 2``: from
    any hole the walk looks to the window's outer side), the walk ends after the last region pixel of the window,
    none when that is the outer side's own (the run goes through) or there is none: that pixel is looked for from
    the outer side, without testing the run's pixels."""
    h, w = sub.shape
    n = w1 - w0 + 1
    first = w1 if outward < 0 else w0
    step = -1 if outward < 0 else 1
    rows = np.empty(h, dtype=np.int64)
    cols = np.empty(h, dtype=np.float64)
    k = 0
    backward = max_hole >= n - 2
    for i in range(h):
        v = float(v0 + i)
        sure = v >= v_sure_lo and v <= v_sure_hi
        if backward:
            last = -1
            for j in range(n - 1, -1, -1):
                c = first + step * j - c0
                if 0 <= c < w and _right_pixel_in(sub, i, c, c0, v0, u0, table, gate, row_margin, sure):
                    if j < n - 1:
                        last = j
                    break
            if last >= 0:
                rows[k] = v0 + i
                cols[k] = float(first + step * last)
                k += 1
            continue
        start = n
        for j in range(n):
            c = first + step * j - c0
            if 0 <= c < w and _right_pixel_in(sub, i, c, c0, v0, u0, table, gate, row_margin, sure):
                start = j
                break
        last = -1
        j = start + 1
        while j < n:
            c = first + step * j - c0
            if 0 <= c < w and _right_pixel_in(sub, i, c, c0, v0, u0, table, gate, row_margin, sure):
                j += 1
                continue
            q = j + 1
            while q < n and q - j <= max_hole:
                c = first + step * q - c0
                if 0 <= c < w and _right_pixel_in(sub, i, c, c0, v0, u0, table, gate, row_margin, sure):
                    break
                q += 1
            if q < n and q - j <= max_hole:
                j = q
            else:
                last = j - 1
                break
        if last >= 0:
            rows[k] = v0 + i
            cols[k] = float(first + step * last)
            k += 1
    return rows[:k].copy(), cols[:k].copy()


@njit(cache=True)
def _right_row_ends(sub, c0, v0, u0, table, gate, row_margin, w0, w1, outward, max_hole):  # pragma: no cover
    """:func:`_block_row_ends` (window columns ``w0 … w1``) of the block :func:`_right_band` makes of ``sub`` (rows
    ``v0 …``, columns ``c0 …``), each pixel tested (:func:`_right_pixel`) only when the walk reads it: the same
    walk, the same rows and columns (:func:`_right_row_ends_in` with no row tested on its disparity alone)."""
    return _right_row_ends_in(sub, c0, v0, u0, table, gate, row_margin, w0, w1, outward, max_hole, np.inf, -np.inf)


@njit(cache=True)
def _right_band(sub, c0, v0, u0, table, gate, row_margin):  # pragma: no cover - numba
    """:func:`right_region` on the box ``sub`` (h, w) of right disparities at rows ``v0…``, columns ``c0…``,
    for a prediction whose window's columns are ``u0, u0 + 1, …`` (consecutive), ``table`` its
    :attr:`~stablemarks.planes.PlanePrediction.band_table`: the left column ``u = x + d`` must lie in the window;
    the band there is interpolated as ``np.interp`` does (``(y[j+1] − y[j]) · frac + y[j]``, the differences
    from the table). The rows of the band are interpolated only for pixels whose disparity is in it (the same
    mask, fewer operations)."""
    h, w = sub.shape
    K = table.shape[0]
    u_last = u0 + K - 1
    out = np.zeros((h, w), dtype=np.bool_)
    for i in range(h):
        v = float(v0 + i)
        for k in range(w):
            disp = float(sub[i, k])
            u = float(c0 + k) + disp
            if not (u >= u0 and u <= u_last):  # also NaN
                continue
            j = int(u - u0)
            if j == K - 1:
                out[i, k] = (abs(disp - table[j, 0]) <= gate * table[j, 2] and v >= table[j, 4] - row_margin
                             and v <= table[j, 6] + row_margin)
                continue
            frac = u - float(u0 + j)
            dp = table[j, 1] * frac + table[j, 0]
            sp = table[j, 3] * frac + table[j, 2]
            if not abs(disp - dp) <= gate * sp:
                continue
            vt = table[j, 5] * frac + table[j, 4]
            vb = table[j, 7] * frac + table[j, 6]
            out[i, k] = v >= vt - row_margin and v <= vb + row_margin
    return out


def boundary_window(config: LandmarkConfig, window_px: float) -> float:
    """The SAD window width [px] the boundary search allows for: ``landmarks.boundary_window_px`` when set, else
    ``window_px`` (the block matcher's ``sad.block_size``)."""
    return config.boundary_window_px if config.boundary_window_px is not None else window_px


def search_boundary(
    camera: StereoCamera,
    fit: PlaneFit,
    edge: str,
    disparity_right: np.ndarray | None,
    members_u: np.ndarray,
    config: LandmarkConfig = LandmarkConfig(),
    plane_config: PlaneConfig = PlaneConfig(),
    window_px: float = 15.0,
    border_sigma_px: float | tuple[float | None, float | None] | None = None,
    bridge_px: int | None = None,
) -> Boundary | None:
    """Find a free edge of a fitted plane in both images (Sec 3.2) → ``P_b, Σ_Pb`` on the plane.

    ``members_u`` (k, 2): left and right columns of the plane's member segment pairs, for the rule that
    a boundary found inside the outermost segment is moved to it. Returns None when the region does not
    reach the search window in the left image. ``window_px``: the SAD window width used when
    ``config.boundary_window_px`` is None. ``border_sigma_px``: σ [px] of the boundary's column beyond the rows'
    spread and the line noise, shared by both images: ``(snapped, free)`` — when the boundary was moved onto a
    member segment at the edge (``noise.boundary_px``) and when it is the region's border itself
    (``noise.free_boundary_px``; block matching moves a depth edge by up to half the window), or one value for
    both; None: a uniform allowance over the window, ``w / sqrt(12)``.
    ``bridge_px``: the widest hole in the region a row's run is followed across
    (default ``w // 2``, pixels the disparity checks left out; :func:`landmarks_on_plane` allows the whole
    window where the map has no other wall beyond the edge, so that a textureless strip just inside the edge,
    a joint or a door frame, does not end the region early).
    """
    return _search_boundary(camera, fit, edge, disparity_right, members_u, config, plane_config, window_px,
                            border_sigma_px, bridge_px, _inner_columns(camera, fit.X, fit.plane, edge))


def _search_boundary(camera: StereoCamera, fit: PlaneFit, edge: str, disparity_right: np.ndarray | None,
                     members_u: np.ndarray, config: LandmarkConfig, plane_config: PlaneConfig, window_px: float,
                     border_sigma_px, bridge_px: int | None, u_inner: np.ndarray) -> Boundary | None:
    """:func:`search_boundary` with the wall's inner columns ``u_inner`` (:func:`_inner_columns` of the edge: which
    way is "outward" in each image, from a point inside the wall towards the edge) already known."""
    w = boundary_window(config, window_px)
    pred = fit.prediction
    plane = fit.plane
    e = pred.edges[edge]
    X = fit.X
    # the boundary's columns and their variances, as Python floats until the Boundary is made (the same doubles as
    # in the float64 arrays they were kept in; unset: 0.0)
    u_b = [0.0, 0.0]
    var_b = [0.0, 0.0]
    rows_used = 0
    snapped = False
    # each image's region as a block (rows v0 …, columns u0 …) of an image W wide, empty outside it: the left
    # region's box rows, the right region computed in the search window only (_block_boundary_columns)
    H, W = fit.region.shape
    v0, v1, _ = fit.box[0].indices(H)
    regions = [(fit.region[v0:max(v0, v1)], v0, 0), None]
    e_u = e.u.tolist()
    windows = [e.window(0, config.search_sigma), e.window(1, config.search_sigma)]
    if disparity_right is not None and math.isfinite(e_u[0]) and math.isfinite(e_u[1]):
        lo_r, hi_r = windows[1]
        # the right region's block is not made: its pixels are tested as the row walk reads them
        # (_right_row_ends; _right_block's box and edge cases)
        regions[1] = _right_box(pred, disparity_right, plane_config.row_margin_px,
                                (math.floor(lo_r) - 1, math.ceil(hi_r) + 1))
    u_in = u_inner.tolist()
    outwards = [-1 if e_u[img] < u_in[img] else 1 for img in (0, 1)]
    right_found = True
    k_mad = float(config.row_outlier_mad)
    for img in (0, 1):
        outward = outwards[img]
        lo, hi = windows[img]
        if img == 0:  # the left region exists only inside the plane's predicted window
            p_lo, p_hi = pred.window
            lo, hi = max(lo, p_lo), min(hi, p_hi)
        if regions[img] is None:
            n_rows = 0
        else:
            block, bv0, bu0 = regions[img]
            hole = int(w // 2) if bridge_px is None else int(bridge_px)
            # each image's boundary columns (_block_boundary_columns, _right_boundary_columns), then robust_rows and
            # minimum_variance_column of the rows kept (_robust_minimum_variance), in one numba call
            Wi = W if img == 0 else disparity_right.shape[1]
            c0 = math.floor(min(max(lo, 0), Wi - 1))
            c1 = math.ceil(min(max(hi, 0), Wi - 1))
            if c1 < c0:
                n_rows, m, var = 0, np.nan, np.nan  # no column: no row (what _robust_minimum_variance gives of none)
            elif img == 0:
                n_rows, m, var = _left_end_column(np.ascontiguousarray(block, dtype=np.bool_), int(bv0), int(bu0), c0,
                                                  c1, int(outward), int(hole), k_mad, float(lo), float(hi))
            else:
                n_rows, m, var = _right_end_column(block, int(bu0), int(bv0), int(pred.columns[0]), pred.band_table,
                                                   float(pred.gate), float(plane_config.row_margin_px), c0, c1,
                                                   int(outward), int(hole), k_mad, float(lo), float(hi))
        if n_rows < config.min_boundary_rows:
            if img == 0:
                return None
            right_found = False
            continue
        if img == 0:
            rows_used = n_rows
        u_b[img] = float(m)
        var_b[img] = float(var + camera.sigma_img**2)
    # A boundary placed inside the outermost segment of the region is moved to that segment. Block matching
    # erodes or fattens a region's border by up to the window, so only segments within one window beyond it
    # count (farther ones lie on a wall in line with this one, past a gap). The move takes one segment *pair*
    # in both images: moving each image's border to its own outermost line can take two different lines, whose
    # disparity puts the edge metres off the wall (hall, screens at 10 m: 3–6 px off the plane's disparity,
    # 0.1 m along it). The pair's right line must lie within one window of the right border too.
    if len(members_u):
        # the member pair farthest beyond the left border within one window (first of equals; on Python floats)
        (ub0, ub1), (o0, o1) = u_b, outwards
        k, farthest = -1, 0.0
        members = members_u.tolist()
        for q, (m0, m1) in enumerate(members):
            b0 = (m0 - ub0) * o0
            if 0 < b0 <= w and (not right_found or abs((m1 - ub1) * o1) <= w) and (k < 0 or b0 > farthest):
                k, farthest = q, b0
        if k >= 0:
            u_b = [float(v) for v in members[k]]
            snapped = True
            # the edge is now that segment pair's lines, each good to the line noise: the spread of the
            # region's border rows it replaced no longer applies (what may lie between line and edge is
            # the shared ``border`` term below)
            var_b = [float(camera.sigma_img**2)] * 2
            right_found = True
    if right_found and not snapped:
        # The two borders were found apart. Block matching moves a depth edge in 3-D (both images the same way),
        # so the pair keeps the wall's disparity; a right border more than half a window from it is another
        # edge (hall, a door jamb at 9 m: the right border 10–26 px off, the left within 1 px; the edge came out
        # 0.15 m along the wall and every feature modelled from it with it).
        d_here, _ = pred.disparity_at(u_b[0])
        if abs(u_b[0] - u_b[1] - float(d_here)) > w / 2.0:
            right_found = False
    if not right_found:
        # right image unusable: take the column where the fitted plane puts the left boundary
        d_here, _ = pred.disparity_at(u_b[0])
        u_b[1] = u_b[0] - float(d_here)
        var_b[1] = float(config.fallback_sigma_px**2)
    # The window term is one physical effect seen by both disparity images (the window straddling the
    # depth edge shifts the region's border the same way in 3D): it is shared, fully correlated.
    border = border_sigma_px if isinstance(border_sigma_px, tuple) else (border_sigma_px, border_sigma_px)
    border = border[0] if snapped else border[1]
    var_w = w**2 / 12.0 if border is None else float(border) ** 2
    vb0, vb1 = var_b
    cov_uv = np.array([[vb0 + var_w, var_w], [var_w, vb1 + var_w]])  # np.diag(var_b) + var_w
    sigma_u = np.array([math.sqrt(vb0 + var_w), math.sqrt(vb1 + var_w)])  # IEEE square roots, as np.sqrt's
    # triangulate's branch for one column pair with a full covariance (_triangulate_one), called directly
    P, cov = camera._triangulate_one(u_b[0], u_b[1], X, cov_uv)
    p0, p1 = P.tolist()
    if not (math.isfinite(p0) and math.isfinite(p1)):
        # non-positive disparity from two independent searches: intersect the left ray with the plane
        d_here, _ = pred.disparity_at(u_b[0])
        u_b[1] = u_b[0] - float(d_here)
        P, cov = camera._triangulate_one(u_b[0], u_b[1], X, cov_uv)
    P_hat, cov_hat = fit.fuse_point(P, cov)
    t = _inward(plane, edge)
    sigma_along = float(np.sqrt(t @ cov_hat @ t))
    sigma_m = np.nan
    u_b = np.array(u_b)
    if config.filter_boundary_sigma == "measured":
        # the same without the window allowance: the rows' spread and the image noise only (DESIGN §4)
        _, cov_m = camera.triangulate(u_b[0], u_b[1], X, cov_uv=np.diag(var_b))
        _, cov_m = fit.fuse_point(P, cov_m)
        sigma_m = float(np.sqrt(t @ cov_m @ t))
    return Boundary(plane.id, edge, u_b, sigma_u, P_hat, cov_hat, sigma_along, snapped, rows_used, t, sigma_m,
                    cov_uv, np.diag(var_b) if config.filter_boundary_sigma == "measured" else None)


def model_features(
    camera: StereoCamera,
    fit: PlaneFit,
    boundary: Boundary,
    pairs,
    member_idx: np.ndarray,
    contrast: np.ndarray | None = None,
    config: LandmarkConfig = LandmarkConfig(),
) -> list[Candidate]:
    """Relative model of the plane's member pairs w.r.t. the boundary (Eqs 12–17), ranked from the edge.
    ``contrast`` (M,): each pair's brightness step [gray levels] (Candidate.contrast; unknown: inf).

    Each candidate also carries what the selection needs to tell a line on the wall from one in front of it:
    the innovation of its point-on-plane update (``wall_offset`` and its σ: the triangulated point against
    the fitted line, Eq 12) and the margin of its heights (``config.row_sigma_px`` rows and the depth's σ).
    """
    plane = fit.plane
    X = fit.X
    edge = boundary.edge
    t = _inward(plane, edge)
    P_edge = plane.edge(edge)
    k = np.asarray(member_idx, dtype=int)
    P_f, cov_f = camera.triangulate(pairs.u_left[k], pairs.u_right[k], X)
    ok = np.isfinite(P_f).all(axis=-1)
    if not ok.any():
        return []
    k, P_f, cov_f = k[ok], P_f[ok], cov_f[ok]
    G, var_G, var_G_fit = fit.innovation(P_f, cov_f)  # is the line on the fitted wall at all?
    P_hat, cov_hat = fit.fuse_point(P_f, cov_f)
    d_p = (P_hat - boundary.P) @ t
    sigma_f = np.sqrt(np.einsum("i,kij,j->k", t, cov_hat, t))
    # heights: z = h − (v − c_v) Z / f; σ_z² = (Z σ_v / f)² + ((h − z) σ_Z / Z)². The element-wise parts (to_camera's
    # depth, heights, the ray from the left optical centre, its length and direction; then the heights' margin, var_s,
    # Eqs 15 and 17) in two numba passes (_feature_geometry, _feature_margins): the array expressions' operations,
    # without their two dozen small NumPy calls; the einsums and the products with a vector stay NumPy's
    cx, cy, _, c, s = camera._frame(X)
    h = float(camera.mount_height)
    Zc, z_high, z_low, dist, view = _feature_geometry(
        P_hat, cx, cy, c, s, np.asarray(pairs.v_top[k], dtype=float), np.asarray(pairs.v_bottom[k], dtype=float),
        float(camera.cv), float(camera.f), h)
    var_Z = np.einsum("ki,kij,kj->k", view, cov_hat, view)
    margin, var_s, P_model, cov_model = _feature_margins(
        Zc, z_high, z_low, var_Z, sigma_f, d_p, h, float(config.row_sigma_px), float(camera.f),
        float(config.off_wall_sigma), float(boundary.sigma_along**2), np.asarray(P_edge, dtype=float),
        np.asarray(t, dtype=float))
    incidence = np.arccos(np.clip(np.abs(view @ plane.normal), 0.0, 1.0))
    J_shared, sigma_own, cov_shared = relative_error_model(camera, fit, boundary, pairs.u_left[k], pairs.u_right[k],
                                                           t, config.filter_boundary_sigma == "measured")
    # the per-candidate numbers as Python floats in one conversion per array (``tolist``: the same values as
    # ``float(a[j])``; the square root of var_G element-wise, as of each element)
    d_l, sf_l, zl_l, zh_l, G_l, sG_l, sGf_l, m_l, dist_l, inc_l = (
        a.tolist() for a in (d_p, sigma_f, z_low, z_high, G, np.sqrt(var_G), np.sqrt(var_G_fit), margin, dist,
                             incidence))
    ls_l, ul_l, ur_l, vt_l, vb_l = (np.asarray(a, dtype=float)[k].tolist() for a in (
        pairs.length_similarity, pairs.u_left, pairs.u_right, pairs.v_top, pairs.v_bottom))
    c_l = [np.inf] * len(k) if contrast is None else np.asarray(contrast, dtype=float)[k].tolist()
    so_l = [np.nan] * len(k) if J_shared is None else sigma_own.tolist()
    k_l = k.tolist()
    # the rows of the per-candidate arrays as lists of views (what ``a[j]`` gives), and each candidate made as
    # _new_candidate makes it from a dict literal (a literal is built faster than ``dict(**kw)``; its keys, the same
    # for every candidate, are checked once): ~1.5 µs a candidate instead of ~3
    Pm_l, cm_l, Ph_l, ch_l = list(P_model), list(cov_model), list(P_hat), list(cov_hat)
    J_l = [None] * len(k_l) if J_shared is None else list(J_shared)
    plane_id, plane_label, sigma_b, sigma_bm = plane.id, plane.label, boundary.sigma_along, \
        boundary.sigma_along_measured
    out = []
    new = object.__new__
    for rank, j in enumerate(np.argsort(d_p, kind="stable").tolist()):
        values = {
            "plane_id": plane_id, "plane_label": plane_label, "index": rank + 1, "pair": k_l[j], "edge": edge,
            "s": d_l[j], "sigma_b": sigma_b, "sigma_f": sf_l[j], "P": Pm_l[j], "cov": cm_l[j],
            "z_low": zl_l[j], "z_high": zh_l[j], "length_similarity": ls_l[j], "u_left": ul_l[j], "u_right": ur_l[j],
            "v_top": vt_l[j], "v_bottom": vb_l[j], "selected": False, "reason": "",
            "P_observed": Ph_l[j], "cov_observed": ch_l[j], "contrast": c_l[j],
            "sigma_b_measured": sigma_bm, "wall_offset": G_l[j], "sigma_wall_offset": sG_l[j],
            "sigma_wall_fit": sGf_l[j], "height_margin": m_l[j], "range": dist_l[j], "incidence": inc_l[j],
            "shared_jacobian": J_l[j], "shared_cov": cov_shared, "sigma_own": so_l[j]}
        if not out:
            out.append(_new_candidate(values))
            continue
        c = new(Candidate)
        c.__dict__.update(values)
        out.append(c)
    return out


@njit(cache=True, error_model="numpy")
def _feature_geometry(P_hat, cx, cy, c, s, v_top, v_bottom, cv, f, h):  # pragma: no cover - numba
    """:func:`model_features`' points ``P_hat`` (n, 2) seen from the left optical centre ``(cx, cy)`` (heading ``(c,
    s)``): the depth ``Z_c`` (:meth:`~stablemarks.geometry.StereoCamera.to_camera`), the heights of the rows
    ``v_top``, ``v_bottom`` there (:meth:`~stablemarks.geometry.StereoCamera.heights`), the distance ``hypot`` of
    the ray and its direction — each the array expression's operations on one point."""
    n = P_hat.shape[0]
    Zc = np.empty(n)
    z_high = np.empty(n)
    z_low = np.empty(n)
    dist = np.empty(n)
    view = np.empty((n, 2))
    for i in range(n):
        dx = P_hat[i, 0] - cx
        dy = P_hat[i, 1] - cy
        z = c * dx + s * dy
        Zc[i] = z
        z_high[i] = h - (v_top[i] - cv) * z / f
        z_low[i] = h - (v_bottom[i] - cv) * z / f
        d = np.hypot(dx, dy)
        dist[i] = d
        view[i, 0] = dx / d
        view[i, 1] = dy / d
    return Zc, z_high, z_low, dist, view


@njit(cache=True, error_model="numpy")
def _feature_margins(Zc, z_high, z_low, var_Z, sigma_f, d_p, h, row_sigma_px, f, off_wall_sigma, var_b, P_edge,
                     t):  # pragma: no cover - numba
    """:func:`model_features`' height margins ``k σ`` (``k = off_wall_sigma``, ``σ² = (Z σ_v / f)² + (span / Z)²
    σ_Z²``), ``var_s = σ_b² + σ_f²`` and each candidate's Eq 15 point ``P_edge + d_p t`` and Eq 17 covariance ``var_s
    t tᵀ``: the array expressions' operations per candidate (``np.maximum``'s NaN, squares as products)."""
    n = Zc.shape[0]
    margin = np.empty(n)
    var_s = np.empty(n)
    P_model = np.empty((n, 2))
    cov_model = np.empty((n, 2, 2))
    t00, t01, t11 = t[0] * t[0], t[0] * t[1], t[1] * t[1]
    t10 = t[1] * t[0]
    for i in range(n):
        z = Zc[i]
        srz = z * row_sigma_px / f
        span = np.maximum(abs(h - z_low[i]), abs(h - z_high[i]))
        q = span / z
        margin[i] = off_wall_sigma * np.sqrt(srz * srz + q * q * var_Z[i])
        v = var_b + sigma_f[i] * sigma_f[i]
        var_s[i] = v
        P_model[i, 0] = P_edge[0] + d_p[i] * t[0]
        P_model[i, 1] = P_edge[1] + d_p[i] * t[1]
        cov_model[i, 0, 0] = v * t00
        cov_model[i, 0, 1] = v * t01
        cov_model[i, 1, 0] = v * t10
        cov_model[i, 1, 1] = v * t11
    return margin, var_s, P_model, cov_model


def _new_candidate(values: dict) -> Candidate:
    """``Candidate(**values)`` with every field given, without the frozen dataclass's ``__init__`` (~35 fields set
    one by one through ``object.__setattr__``: ~8 µs a candidate): the same object (Candidate has no
    ``__post_init__``), its fields in the same order. (See :func:`_replace`.)"""
    if values.keys() != _CANDIDATE_FIELDS:
        raise TypeError(f"Candidate fields: expected {sorted(_CANDIDATE_FIELDS)}, got {sorted(values)}")
    new = object.__new__(Candidate)
    new.__dict__.update(values)
    return new


def relative_error_model(camera: StereoCamera, fit: PlaneFit, boundary: Boundary, u_left, u_right, t,
                         measured: bool = False, step_px: float = 0.01, step_line: float = 1e-4):
    """The error model of features' distances ``d = (P̂_f − P̂_b)·t`` along the wall from the boundary, as
    the estimator computes them (triangulate, fuse with the fitted line, Eqs 12–17).

    Returns ``J`` (n, 4) = ``∂d/∂(a, b, u_bl, u_br)`` (what the plane's features share: the line and the
    boundary's columns), ``σ_own`` (n,) the σ of ``d`` from each feature's own columns (σ_img each), and
    ``Σ_shared`` (4, 4) = blockdiag(Σ_R, Σ_ub) (``measured``: the boundary without the SAD window
    allowance). Derivatives by central differences of the estimator itself (``step_px`` [px],
    ``step_line`` [m, 1]): the fusion's gain depends on the line, so no closed form is simpler. ``(None, None,
    None)`` when the boundary carries no column covariance.

    All perturbed columns are triangulated and fused in one batch each; a step ``h`` of the line's offset is the
    points moved by ``−h`` along the normal and back (``G`` depends on ``a`` only through ``offset − a``, and the
    gain not at all), so only the slope's two steps need a line of their own.
    """
    cov_ub = boundary.cov_uv_measured if measured and boundary.cov_uv_measured is not None else boundary.cov_uv
    if cov_ub is None:
        return None, None, None
    u_f = np.stack([np.asarray(u_left, dtype=float).ravel(), np.asarray(u_right, dtype=float).ravel()], axis=-1)
    cx, cy, _, c, s = camera._frame(fit.X)
    plane = fit.plane
    J, own = _relative_model(u_f, np.asarray(boundary.u, dtype=float), np.asarray(cov_ub, dtype=float),
                             float(camera.f), float(camera.baseline), float(camera.cu), float(camera.sigma_img), cx, cy,
                             c, s, plane.P1, plane.direction, plane.normal, float(fit.a), float(fit.b), float(fit.s0),
                             np.asarray(fit.cov_R, dtype=float), np.asarray(t, dtype=float), float(step_px),
                             float(step_line))
    cov_shared = np.zeros((4, 4))
    cov_shared[:2, :2] = fit.cov_R
    cov_shared[2:, 2:] = cov_ub
    if not (np.isfinite(J).all() and np.isfinite(own).all()):
        return None, None, None
    return J, np.sqrt(own), cov_shared


@njit(cache=True, error_model="numpy", inline="always")
def _triangulate_one(ul, ur, f, baseline, cu, cx, cy, c, s):  # pragma: no cover - numba
    """:meth:`~stablemarks.geometry.StereoCamera.triangulate` of one column pair with a pose (its left optical centre
    ``(cx, cy)``, heading ``(c, s)``): the world point and the Jacobian ``∂(x, y)/∂(u_l, u_r)``, ``(p0, p1), (J00,
    J01, J10, J11)``, by the same element-wise operations (NaN where ``u_l − u_r <= 0``)."""
    d = ul - ur
    d = d if d > 0 else np.nan
    fb = f * baseline
    Zc = fb / d
    Xc = (ul - cu) * Zc / f
    dZ_dur = fb / (d * d)
    dZ_dul = -dZ_dur
    dX_dul = Zc / f + (ul - cu) * dZ_dul / f
    dX_dur = (ul - cu) * dZ_dur / f
    return ((cx + c * Zc + s * Xc, cy + s * Zc - c * Xc),
            (s * dX_dul + c * dZ_dul, s * dX_dur + c * dZ_dur, -c * dX_dul + s * dZ_dul, -c * dX_dur + s * dZ_dur))


@njit(cache=True, error_model="numpy")
def _relative_model(u_f, u_b, cov_ub, f, baseline, cu, sigma_img, cx, cy, c, s, P1, tw, nrm, a, b, s0, cov_R, t,
                    step_px, step_line):  # pragma: no cover - numba
    """:func:`relative_error_model`'s central differences for features at columns ``u_f`` (n, 2) from the boundary at
    ``u_b`` (2,) with column covariance ``cov_ub`` (2, 2): ``J`` (n, 4) and ``own`` (n,) (the variance of ``d`` from
    the feature's own columns). Per feature and step what the former NumPy code computed for all at once:
    triangulated (:func:`_triangulate_one`; the feature's covariance ``σ_img² J Jᵀ``, the boundary's ``J Σ_ub
    Jᵀ``), fused with the fitted line (:func:`~stablemarks.planes.fuse_one`), the offset's step as the point moved
    along the normal and back, the slope's as the line turned; the distances along ``t``. The 2×2 products and the
    dot products are summed left to right (NumPy's may fuse multiply-adds: the values may differ in the last bits,
    the derivatives to about 1e-12 of their size); ~130 µs of NumPy calls on tiny arrays per plane before."""
    n = u_f.shape[0]
    steps = ((0.0, 0.0), (step_px, 0.0), (-step_px, 0.0), (0.0, step_px), (0.0, -step_px))
    s2 = sigma_img * sigma_img

    def along(x0, x1):  # (x0, x1) · t
        return x0 * t[0] + x1 * t[1]

    # the boundary: its five column variants fused with the line (B[0 … 4]), the base moved ∓h along the normal
    # (B[5], B[6]), and the base fused with the line turned to b ± h (Bs[0], Bs[1])
    B = np.empty((7, 2))
    Bs = np.empty((2, 2))
    base_cov = (0.0, 0.0, 0.0, 0.0)
    base_p = (0.0, 0.0)
    for k in range(5):
        p, (j00, j01, j10, j11) = _triangulate_one(u_b[0] + steps[k][0], u_b[1] + steps[k][1], f, baseline, cu, cx,
                                                   cy, c, s)
        m00 = j00 * cov_ub[0, 0] + j01 * cov_ub[1, 0]  # J Σ_ub, then (J Σ_ub) Jᵀ
        m01 = j00 * cov_ub[0, 1] + j01 * cov_ub[1, 1]
        m10 = j10 * cov_ub[0, 0] + j11 * cov_ub[1, 0]
        m11 = j10 * cov_ub[0, 1] + j11 * cov_ub[1, 1]
        cov = (m00 * j00 + m01 * j01, m00 * j10 + m01 * j11, m10 * j00 + m11 * j01, m10 * j10 + m11 * j11)
        (B[k, 0], B[k, 1]), _ = fuse_one(p[0], p[1], cov[0], cov[1], cov[2], cov[3], P1, tw, nrm, a, b, s0, cov_R)
        if k == 0:
            base_p, base_cov = p, cov
    _shifted(B, base_p, base_cov, P1, tw, nrm, a, b, s0, cov_R, step_line)
    for i, h in enumerate((step_line, -step_line)):
        (Bs[i, 0], Bs[i, 1]), _ = fuse_one(base_p[0], base_p[1], base_cov[0], base_cov[1], base_cov[2], base_cov[3],
                                           P1, tw, nrm, a, b + h, s0, cov_R)
    J = np.empty((n, 4))
    own = np.empty(n)
    F = np.empty((7, 2))
    Fs = np.empty((2, 2))
    for i in range(n):
        for k in range(5):
            p, (j00, j01, j10, j11) = _triangulate_one(u_f[i, 0] + steps[k][0], u_f[i, 1] + steps[k][1], f, baseline,
                                                       cu, cx, cy, c, s)
            cov = ((s2 * j00) * j00 + (s2 * j01) * j01, (s2 * j00) * j10 + (s2 * j01) * j11,
                   (s2 * j10) * j00 + (s2 * j11) * j01, (s2 * j10) * j10 + (s2 * j11) * j11)
            (F[k, 0], F[k, 1]), _ = fuse_one(p[0], p[1], cov[0], cov[1], cov[2], cov[3], P1, tw, nrm, a, b, s0, cov_R)
            if k == 0:
                base_p, base_cov = p, cov
        _shifted(F, base_p, base_cov, P1, tw, nrm, a, b, s0, cov_R, step_line)
        for q, h in enumerate((step_line, -step_line)):
            (Fs[q, 0], Fs[q, 1]), _ = fuse_one(base_p[0], base_p[1], base_cov[0], base_cov[1], base_cov[2],
                                               base_cov[3], P1, tw, nrm, a, b + h, s0, cov_R)

        J[i, 0] = (along(F[5, 0] - B[5, 0], F[5, 1] - B[5, 1]) - along(F[6, 0] - B[6, 0], F[6, 1] - B[6, 1])) / (
            2 * step_line)
        J[i, 1] = (along(Fs[0, 0] - Bs[0, 0], Fs[0, 1] - Bs[0, 1]) - along(Fs[1, 0] - Bs[1, 0], Fs[1, 1] - Bs[1, 1])
                   ) / (2 * step_line)
        J[i, 2] = (along(F[0, 0] - B[1, 0], F[0, 1] - B[1, 1]) - along(F[0, 0] - B[2, 0], F[0, 1] - B[2, 1])) / (
            2 * step_px)
        J[i, 3] = (along(F[0, 0] - B[3, 0], F[0, 1] - B[3, 1]) - along(F[0, 0] - B[4, 0], F[0, 1] - B[4, 1])) / (
            2 * step_px)
        ol = (along(F[1, 0] - B[0, 0], F[1, 1] - B[0, 1]) - along(F[2, 0] - B[0, 0], F[2, 1] - B[0, 1])) / (
            2 * step_px) * sigma_img
        orr = (along(F[3, 0] - B[0, 0], F[3, 1] - B[0, 1]) - along(F[4, 0] - B[0, 0], F[4, 1] - B[0, 1])) / (
            2 * step_px) * sigma_img
        own[i] = ol * ol + orr * orr
    return J, own


@njit(cache=True, error_model="numpy", inline="always")
def _shifted(out, p, cov, P1, tw, nrm, a, b, s0, cov_R, h):  # pragma: no cover - numba
    """Rows 5 and 6 of :func:`_relative_model`'s fused points: the base point ``p`` (covariance ``cov``) moved by
    ``∓h`` along the normal, fused with the line, and moved back (the line's offset ``a ± h``)."""
    for row, sign in ((5, -1.0), (6, 1.0)):
        (x0, x1), _ = fuse_one(p[0] + sign * h * nrm[0], p[1] + sign * h * nrm[1], cov[0], cov[1], cov[2], cov[3],
                               P1, tw, nrm, a, b, s0, cov_R)
        out[row, 0] = x0 - sign * h * nrm[0]
        out[row, 1] = x1 - sign * h * nrm[1]


def select(candidates: list[Candidate], boundaries: list[Boundary], config: LandmarkConfig = LandmarkConfig(),
           z_range: tuple[float, float] | None = None):
    """Sec 4 and beyond: a line must be on its wall (:func:`on_wall_reason`), then the near-boundary 3σ rule
    against every visible free edge, length similarity (Eq 18), contrast, range and incidence. ``z_range``:
    the wall's mapped bottom and top [m] (default: the candidates' plane's is not checked)."""
    out = []
    first = {}  # the first boundary of each (plane, edge), as the candidates look them up
    for b in boundaries:
        first.setdefault((b.plane_id, b.edge), b)
    for c in candidates:
        reason = on_wall_reason(c, config, z_range)
        # the feature where its relative model puts it (``s`` from the boundary it was modelled from): the
        # distance to the wall's other end is then measured the same way as to this one (a wall's far end placed
        # from the map's length is exactly ``length − s`` away; the triangulated point alone is off along the
        # wall by its depth error at an angle, 3 cm at 6 m and 15°, enough to take a poster's far edge for a
        # feature once the boundaries are known to a few mm); made when first needed
        P_c = None
        for b in boundaries:
            if reason:
                break
            if b.plane_id != c.plane_id:
                continue
            if b.edge == c.edge:
                dist = c.s
            else:  # the wall's other end, found in view or placed from the map: distance inward from it
                if P_c is None:
                    ref = first.get((c.plane_id, c.edge))
                    P_c = ref.P + c.s * ref.inward if ref is not None else c.P_observed
                dist = float((P_c - b.P) @ b.inward)
            sigma_b = b.sigma_along
            if config.boundary_rule == "combined":
                margin = config.boundary_sigma * np.hypot(sigma_b, c.sigma_f)
            else:
                margin = config.boundary_sigma * (sigma_b + c.sigma_f)
            if dist < -margin:
                reason = REASON_OUTSIDE
                break
            if abs(dist) <= margin:
                reason = REASON_NEAR_BOUNDARY
                break
        if not reason and c.length_similarity < config.min_length_similarity:
            reason = REASON_LENGTH
        if not reason and c.contrast < config.min_contrast:
            reason = REASON_CONTRAST
        if not reason and c.range > config.max_range:
            reason = REASON_FAR
        if not reason and c.incidence > math.radians(config.max_incidence_deg):
            reason = REASON_OBLIQUE
        out.append(_replace(c, selected=not reason, reason=reason))
    return out


def beside_another_line(candidates: list[Candidate], columns, gap_px: float) -> list[Candidate]:
    """``candidates`` with those selected whose left column has another of ``columns`` (the left image's
    segments, [px]) between 1 px and ``gap_px`` from it rejected as :data:`REASON_BESIDE_LINE`
    (:attr:`LandmarkConfig.min_line_gap_px`)."""
    u = np.asarray(columns, dtype=float)
    out = []
    for c in candidates:
        if c.selected:
            d = np.abs(u - c.u_left)
            if np.any((d >= 1.0) & (d < gap_px)):
                c = _replace(c, selected=False, reason=REASON_BESIDE_LINE)
        out.append(c)
    return out


def on_wall_reason(c: Candidate, config: LandmarkConfig, z_range: tuple[float, float] | None = None) -> str:
    """Why candidate ``c`` is not a line on its wall, or "": its triangulated position is off the fitted plane
    by more than ``off_wall_sigma`` σ (:attr:`LandmarkConfig.off_wall_sigma` states the smallest offset
    resolved), or its ends reach beyond the wall's mapped heights ``z_range`` by more than their margin."""
    if abs(c.wall_offset) > config.off_wall_sigma * c.sigma_wall_offset:
        return REASON_OFF_WALL
    if z_range is not None and (c.z_low < z_range[0] - c.height_margin or c.z_high > z_range[1] + c.height_margin):
        return REASON_HEIGHT
    return ""


def _robust_scale(candidates: list[Candidate]) -> tuple[float, int]:
    """``1.4826 · median |G| / σ_line`` over the candidates with a finite offset, and their number (``math.isfinite``
    and :func:`~stablemarks.planes.median` of the finite ratios: NumPy's answers, without its per-call overhead)."""
    z = []
    for c in candidates:
        sigma = c.sigma_wall_line
        if math.isfinite(c.wall_offset) and math.isfinite(sigma) and sigma > 0:
            z.append(abs(c.wall_offset) / sigma)
    return (1.4826 * median(np.array(z)) if z else np.nan), len(z)


def line_noise_scale(candidates: list[Candidate], min_lines: int, floor: float = 0.0) -> float:
    """The lines' column noise in this frame as a fraction of the model's (``noise.sigma_img``), in
    ``[floor, 1]``: ``1.4826 · median |G| / σ_line`` over the candidates (``G`` their offset from the fitted wall,
    ``σ_line`` its σ from the lines' columns alone, :attr:`Candidate.sigma_wall_offset` without the fit's part).
    1 with fewer than ``min_lines`` candidates, or ``min_lines`` 0 (:attr:`LandmarkConfig.off_wall_min_lines`)."""
    if min_lines <= 0:
        return 1.0
    scale, n = _robust_scale(candidates)
    if n < min_lines:
        return 1.0
    return min(1.0, max(floor, scale))


def wall_line_scatter(model: PlaneLandmarks, min_lines: int) -> float:
    """How far one wall's lines lie from its fitted line, as a multiple of the model's line noise
    (``1.4826 · median |G| / σ_line`` over its candidates; NaN with fewer than ``min_lines``, or ``min_lines`` 0).
    Above 1 the lines scatter about the fit more than the line noise allows: the fit or the lines are not of one
    wall. Measured (2–3 trials × 80–100 frames, walls with 10 lines or more): at most 0.72 on lab, room, corridor,
    office and hall (median 0.12–0.24); on a storeroom whose fits mixed the wall with a cabinet and cartons in
    front of it after a blind stretch (heading σ 6°), 13 of 38 wall-frames were above 1, and 13 of the 29
    landmarks entered from them were not on the wall (1 of 6 from the others)."""
    if min_lines <= 0:
        return np.nan
    scale, n = _robust_scale(model.candidates)
    return scale if n >= min_lines else np.nan


def off_wall_by_lines(models: list[PlaneLandmarks], config: LandmarkConfig, sigma_img: float
                      ) -> tuple[list[PlaneLandmarks], float]:
    """The off-wall test again, for the candidates of all the frame's planes, with the line noise that the
    frame's lines show (:func:`line_noise_scale`, at least ``off_wall_floor_px``) in place of the model's
    ``sigma_img`` [px]: returns the models with the candidates it finds off their wall marked "off the wall"
    (the selection's first test: a reason found later, such as "near boundary", gives way to it), and the scale
    (1: nothing changed).

    Before that, a wall whose own lines scatter about its fit beyond the model's line noise
    (:func:`wall_line_scatter` above 1) is not modelled in this frame: every candidate of it is rejected
    (:data:`REASON_SCATTER`, in place of any other reason: no decision is taken from that fit, nor does a
    landmark's re-check read one), with a sentence in its ``rejected_boundaries``, and its lines do not count in
    the frame's scale."""
    kept = []
    limit = 1.0 if config.scatter_px is None else config.scatter_px / sigma_img
    for m in models:
        scatter = wall_line_scatter(m, config.off_wall_min_lines) / limit
        if scatter > 1.0:
            cands = [_replace(c, selected=False, reason=REASON_SCATTER) for c in m.candidates]
            why = (f"plane {m.fit.plane.label!r}: its {len(cands)} lines lie {scatter:.1f} times farther from the "
                   "fitted wall than the line noise allows (the fit mixes the wall with something in front of it, "
                   "or the lines are not the wall's): nothing is modelled from it")
            m = replace(m, candidates=cands, rejected_boundaries=[*m.rejected_boundaries, (None, why)])
        kept.append(m)
    models = kept
    scale = line_noise_scale([c for m in models for c in m.candidates if c.reason != REASON_SCATTER],
                             config.off_wall_min_lines, config.off_wall_floor_px / sigma_img)
    if scale >= 1.0:
        return models, scale
    out = []
    for m in models:
        cands = []
        for c in m.candidates:
            sigma = math.hypot(scale * c.sigma_wall_line, c.sigma_wall_fit)
            if c.reason not in (REASON_OFF_WALL, REASON_HEIGHT, REASON_SCATTER) and \
                    abs(c.wall_offset) > config.off_wall_sigma * sigma:
                c = _replace(c, selected=False, reason=REASON_OFF_WALL)
            cands.append(c)
        out.append(m if all(a is b for a, b in zip(cands, m.candidates, strict=True)) else replace(m, candidates=cands))
    return out, scale


def _replace(c: Candidate, **kw) -> Candidate:
    """``dataclasses.replace(c, **kw)`` for the selection's decisions, without its cost (a frozen dataclass of
    ~35 fields is rebuilt field by field through ``__init__``: ~15 µs, for every candidate of every frame): a
    copy of ``c``'s fields with ``kw`` set. Candidate has no ``__post_init__`` or init-only fields, so the two
    are the same object."""
    unknown = kw.keys() - _CANDIDATE_FIELDS
    if unknown:
        raise TypeError(f"Candidate has no field {sorted(unknown)[0]!r}")
    new = object.__new__(Candidate)
    new.__dict__.update(c.__dict__)
    new.__dict__.update(kw)
    return new


_CANDIDATE_FIELDS = frozenset(f.name for f in fields(Candidate))
_BOUNDARY_FIELDS = frozenset(f.name for f in fields(Boundary))


def _inward(plane, edge: str) -> np.ndarray:
    """Unit direction along the wall from ``edge`` into the wall."""
    return plane.direction if edge == "p1" else -plane.direction


@dataclass(frozen=True)
class PlaneLandmarks:
    """Everything modelled on one plane in one frame; ``rejected_boundaries`` are boundaries found but not
    used, each with the reason (a sentence for the log; ``None`` for the boundary when the fitted wall itself
    was not used, :attr:`gated`)."""

    fit: PlaneFit
    boundaries: list[Boundary]
    members: np.ndarray
    candidates: list[Candidate]
    rejected_boundaries: list[tuple[Boundary | None, str]] = field(default_factory=list)
    searched: list[str] = field(default_factory=list)
    """The free edges searched in this frame (in the searchable part of both images, not hidden, with a depth
    step behind them)."""
    gated: str = ""
    """Why the fitted wall was not used (:func:`fit_disagreements`): ``"turned"`` from the map (its free edges in
    view are then counted as searched and not found), ``"shifted"``, or ``""`` (used)."""
    hidden: list[str] = field(default_factory=list)
    """The searched free edges whose boundary was found to be the silhouette of something nearer standing in front
    of the wall (:func:`occluded_boundary`): the wall's end is hidden from this view, which says nothing about
    where the head looks (:func:`~stablemarks.localizer._edges_missing` does not count them as missed)."""


def landmarks_on_plane(
    camera: StereoCamera,
    fit: PlaneFit,
    pairs,
    left_segments,
    disparity_right: np.ndarray | None,
    config: LandmarkConfig = LandmarkConfig(),
    plane_config: PlaneConfig = PlaneConfig(),
    window_px: float = 15.0,
    valid_columns: tuple[tuple[float, float], tuple[float, float]] | None = None,
    world_map: Map | None = None,
    *,
    cov_X=None,
    border_sigma_px: float | tuple[float | None, float | None] | None = None,
    disparity_left: np.ndarray | None = None,
    disparity_range: tuple[float, float] | None = None,
    unusable: dict[str, str] | None = None,
    memo: dict | None = None,
    boundaries_only: bool = False,
    edge_pairs=None,
) -> PlaneLandmarks:
    """Members, boundary search at every free edge in the window, relative model and selection.

    ``valid_columns``: for the left and the right image, the first and last column where the disparity
    image can hold a match. An edge whose search window reaches beyond them is not searched: the region
    would end there at the image's (or the disparity range's) border, not at the plane's edge.
    ``world_map``: when given, an edge with no depth step behind it (:func:`edge_depth_step`, below
    ``min_edge_step_sigma``) is not searched either. Ends not searched (or not found) are placed from the
    edge that was found with the map's length, and features near them are rejected like near a found one.
    ``cov_X`` (3, 3): the pose covariance; with it a found boundary is checked against the map's free edge
    (:func:`boundary_disagreement`) and not used when it is farther than ``boundary_gate_sigma`` σ.
    ``border_sigma_px``: see :func:`search_boundary`. ``disparity_left``: when given, a selected candidate
    beside something nearer than its wall (:func:`beside_nearer`) is rejected. ``disparity_range``: the least and
    the largest disparity block matching searches [px]; an edge where the wall's predicted disparity may lie
    outside it (``search_sigma`` σ) is not searched: block matching finds nothing there, and the wall's region
    ends where the wall leaves the range, not at its edge (a camera with f·b = 98 px·m and 64 disparities sees
    nothing nearer than 1.5 m: a free-standing panel's end 1.2 m away was found 21 cm inside it).
    ``memo``: a dict (empty at first) passed again with the same ``fit`` and the same other arguments, ``unusable``
    aside: what does not depend on ``unusable`` (the gate, the members, each edge's search and checks, the
    features modelled from one boundary, each line's nearer-side test, the silhouettes) is taken from the earlier
    call instead of computed again (:func:`~stablemarks.pipeline.select_landmarks` models a wall again without
    boundaries :func:`boundaries_apart` flags: ~1 ms a wall). The result is the one computed afresh.
    ``edge_pairs``: the frame's segment pairs that the disparity check did not keep; those on the fitted wall with
    something farther beyond them (:func:`on_wall_pairs`, :func:`edge_lines`; needs ``disparity_left``) are lines a
    boundary may be moved onto, never features.
    ``boundaries_only``: stop once the boundaries are found and checked, before any feature is modelled (no
    candidates): what :func:`boundaries_apart` reads, so that a wall is modelled once, from the boundaries that
    are usable in the frame (with ``memo``, the later full call does not search again).
    """
    if memo is None:
        memo = {}
    elif memo.setdefault("fit", fit) is not fit:
        raise ValueError("landmarks_on_plane: memo was made for another fit")
    if cov_X is not None:
        if "gate" not in memo:
            cov_map = world_map.accuracy_cov if world_map is not None else np.zeros((2, 2))
            memo["gate"] = fit_disagreements(camera, fit, cov_X, cov_map)
        m2, m2_slope = memo["gate"]
        if m2 > config.fit_gate_chi2:
            # A wall turned from the map (a wrong pan turns every wall like this): its free edges in view were
            # expected and are not found. A wall merely shifted (a slip, a kidnap) is left to the widened search.
            in_view = [e for e in fit.plane.free_edges if np.isfinite(fit.prediction.edges[e].u).all()
                       and fit.prediction.edges[e].window(0, config.search_sigma)[1] >= 0
                       and fit.prediction.edges[e].window(0, config.search_sigma)[0] <= camera.width - 1]
            turned = m2_slope > SLOPE_GATE_CHI2
            if not turned:
                in_view = []
            return PlaneLandmarks(fit, [], np.zeros(len(pairs), dtype=bool), [], [
                (None, f"plane {fit.plane.label!r}: the fitted wall is {100 * fit.a:+.1f} cm off and turned "
                       f"{np.degrees(np.arctan(fit.b)):+.1f}° from the map's (Mahalanobis² {m2:.0f} > "
                       f"{config.fit_gate_chi2:g} with the pose's uncertainty): another surface in its band, "
                       "not used")],
                in_view, "turned" if turned else "shifted")
    if "members" not in memo:
        members = plane_members(fit, pairs, left_segments, plane_config)
        # A wall in line with another (two partitions in a row) shares its plane: segments beyond the wall's ends
        # fit it too. Only those between the two ends' search windows are the wall's.
        lo, hi = wall_columns(camera, fit, config.search_sigma)
        members = members & (pairs.u_left >= lo) & (pairs.u_left <= hi)
        idx = np.flatnonzero(members)
        members_u = np.stack([pairs.u_left[idx], pairs.u_right[idx]], axis=-1) if len(idx) else np.zeros((0, 2))
        memo["members"] = members, idx, members_u
        # the dropped pairs on the wall, between the same two ends' windows: lines an end may be moved onto
        memo["edge_pairs"] = None if edge_pairs is None or disparity_left is None else \
            edge_pairs.subset(on_wall_pairs(camera, fit, edge_pairs, config, lo, hi))
    members, idx, members_u = memo["members"]
    boundaries, rejected, searched, hidden = [], [], [], []
    w_sad = boundary_window(config, window_px)
    for edge in fit.plane.free_edges:
        if ("edge", edge) not in memo:
            lines = members_u
            if memo["edge_pairs"] is not None and len(memo["edge_pairs"]) and \
                    np.isfinite(fit.prediction.edges[edge].u).all():
                box = fit.prediction.box(disparity_left.shape[0], plane_config.row_margin_px)
                lines = np.concatenate([members_u, edge_lines(camera, fit, edge, memo["edge_pairs"], disparity_left,
                                                              window_px, box=box)])
            memo[("edge", edge)] = _edge_search(camera, fit, edge, disparity_right, lines, config, plane_config,
                                                window_px, valid_columns, world_map, border_sigma_px,
                                                disparity_range, w_sad, memo.setdefault("inner", {}))
        found, rejected_before = memo[("edge", edge)]  # None: not searched; False: searched, not found
        rejected += rejected_before
        if found is None:
            continue
        searched.append(edge)
        if found is False:
            continue
        b = found
        if unusable and edge in unusable:  # found, but known not to be usable in this frame (boundaries_apart)
            rejected.append((b, unusable[edge]))
            continue
        if ("checked", edge) not in memo:
            memo[("checked", edge)] = _boundary_checks(camera, fit, b, config, window_px, cov_X, disparity_left,
                                                       memo.setdefault("inner", {}))
        why, occluded = memo[("checked", edge)]
        if why:
            rejected.append((b, why))
            if occluded:
                hidden.append(edge)
            continue
        boundaries.append(b)
    if len(boundaries) == 2:
        # Both ends found: the map fixes their distance, whatever the pose. One end snapped onto a line beyond
        # the wall (the corridor: a poster's far edge found 6 cm out, on a line of the wall behind it, so that
        # the poster's own edge passed for a feature) or inside it makes it disagree. Which end is wrong only the
        # pose can tell: an end farther from the map's edge than its gate is not used (with the pose's
        # covariance that gate already ran above), and when both lie inside their gates the pose cannot tell
        # them apart (office, a turn: both ends within 3 σ of a heading 25 mrad uncertain, the one kept was the
        # wrong one, and the seven landmarks modelled from it pulled the pose 3 cm off with NEES 275), so
        # neither is used. Without a pose covariance the less certain end gives way, as before.
        b1, b2 = boundaries
        length = abs(float((b1.P - b2.P) @ fit.plane.direction))
        sigma = float(np.hypot(b1.sigma_along, b2.sigma_along))
        if abs(length - fit.plane.length) > config.boundary_gate_sigma * sigma:
            why = (f"plane {fit.plane.label!r}: the boundaries found at both ends are {100 * length:.1f} cm apart, "
                   f"the map's wall {100 * fit.plane.length:.1f} cm (σ {100 * sigma:.1f} cm)")
            if cov_X is None:
                worse = max(boundaries, key=lambda b: b.sigma_along)
                boundaries.remove(worse)
                rejected.append((worse, f"{why}: the one at {worse.edge} is not used"))
            else:
                z = [abs(off) / sig for off, sig in (boundary_disagreement(b, fit.plane, fit.X, cov_X)
                                                     for b in boundaries)]
                out = [b for b, zi in zip(boundaries, z, strict=True) if zi > config.boundary_gate_sigma]
                if not out:  # both fit the pose: it cannot tell which is wrong
                    out = list(boundaries)
                    why += ": the pose cannot tell which end is wrong, so both are not used"
                else:
                    why += f": the one at {out[0].edge} is off the map's edge, not used"
                for b in out:
                    boundaries.remove(b)
                    rejected.append((b, why))
    if not boundaries or boundaries_only:
        return PlaneLandmarks(fit, boundaries, members, [], rejected, searched, hidden=hidden)
    ref = min(boundaries, key=lambda b: b.sigma_along)
    features = memo.get("features")
    if features is None or features[0] is not ref:  # the features modelled from this very boundary
        step = left_segments.contrast[pairs.left_index] / 4.0  # a Sobel_x response is 4× the step across an edge
        features = memo["features"] = ref, model_features(camera, fit, ref, pairs, idx, step, config)
    cands = features[1]
    # An end of the wall not found in this frame (not free, out of the searchable part of the image, or
    # without a depth step) is still where the map puts it: the wall's length from the edge that was found.
    # Features near it are near a boundary too.
    mapped = mapped_boundaries(fit.plane, boundaries, ref)
    cands = select(cands, boundaries + mapped, config, fit.plane.z)
    if config.min_line_gap_px > 0:
        cands = beside_another_line(cands, left_segments.u, config.min_line_gap_px)
    if disparity_left is not None and config.nearer_fraction < 1.0:
        slope = left_segments.slope[pairs.left_index]
        chosen = [c for c in cands if c.selected]
        # each line's side is its own (the lines are tested one by one): those tested in an earlier call are known
        known = memo.setdefault("sides", {})
        keys = [(c.u_left, c.v_top, c.v_bottom, float(slope[c.pair])) for c in chosen]
        new = list(dict.fromkeys(k for k in keys if k not in known))
        if new:
            sides = beside_nearer_sides(fit, disparity_left, [k[0] for k in new], [k[1] for k in new],
                                        [k[2] for k in new], [k[3] for k in new], window_px, config.nearer_fraction)
            known.update(zip(new, sides.tolist(), strict=True))
        nearer = {id(c) for c, k in zip(chosen, keys, strict=True) if known[k]}
        if config.nearer_fit_sigma is not None:
            # the lines the band's test let through, against the wall as fitted (stricter where the pose is uncertain)
            scored = memo.setdefault("fit_sides", {})
            rest = list(dict.fromkeys(k for c, k in zip(chosen, keys, strict=True) if id(c) not in nearer
                                      and k not in scored))
            if rest:
                z = nearer_than_fit(camera, fit, disparity_left, [k[0] for k in rest], [k[1] for k in rest],
                                    [k[2] for k in rest], [k[3] for k in rest], window_px,
                                    plane_config.sigma_nu(camera))
                scored.update(zip(rest, z.tolist(), strict=True))
            nearer |= {id(c) for c, k in zip(chosen, keys, strict=True)
                       if id(c) not in nearer and scored[k] > config.nearer_fit_sigma}
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER) if id(c) in nearer else c
                 for c in cands]
    if world_map is not None and cov_X is not None and config.nearer_fraction < 1.0 and any(c.selected for c in cands):
        # only the ends whose depth step the disparity test above cannot see: a step within the wall's band
        if "silhouettes" not in memo:
            band_px = float(fit.prediction.gate * median(fit.prediction.sigma_d)) + 1.0  # np.median, without overhead
            memo["silhouettes"] = nearer_silhouettes(camera, fit.X, cov_X, world_map, fit.plane, max_step_px=band_px)
        sil = memo["silhouettes"]
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER)
                 if c.selected and _at_silhouette(camera, c, sil, config.boundary_sigma) else c
                 for c in cands]
    return PlaneLandmarks(fit, boundaries, members, cands, rejected, searched, hidden=hidden)


def on_wall_pairs(camera: StereoCamera, fit: PlaneFit, pairs, config: LandmarkConfig = LandmarkConfig(),
                  lo: float = -np.inf, hi: float = np.inf) -> np.ndarray:
    """(n,) bool: which segment ``pairs`` lie on the fitted wall — triangulated, within ``off_wall_sigma`` σ of it
    (Eq 12's innovation, the candidates' off-wall test), at least half their rows among the fitted region's rows,
    and their left column within ``[lo, hi]`` (:func:`wall_columns`). A pair matched to the wrong line, pixels off
    in disparity, is off the wall."""
    n = len(pairs)
    out = np.zeros(n, dtype=bool)
    if n == 0:
        return out
    ul, ur = np.asarray(pairs.u_left, dtype=float), np.asarray(pairs.u_right, dtype=float)
    r0, r1, _ = fit.box[0].indices(fit.region.shape[0])
    top, bottom = np.asarray(pairs.v_top, dtype=float), np.asarray(pairs.v_bottom, dtype=float)
    overlap = np.minimum(bottom, r1 - 1) - np.maximum(top, r0)
    k = np.flatnonzero((ul >= lo) & (ul <= hi) & (overlap >= 0.5 * (bottom - top)))
    if len(k) == 0:
        return out
    P, cov = camera.triangulate(ul[k], ur[k], fit.X)
    ok = np.isfinite(P).all(axis=-1)
    k, P, cov = k[ok], P[ok], cov[ok]
    if len(k):
        G, var_G, _ = fit.innovation(P, cov)
        out[k[np.abs(G) <= config.off_wall_sigma * np.sqrt(var_G)]] = True
    return out


def edge_lines(camera: StereoCamera, fit: PlaneFit, edge: str, pairs, disparity_left: np.ndarray,
               window_px: float, min_step_px: float = 1.0, box: tuple[slice, slice] | None = None) -> np.ndarray:
    """Columns ``(u_left, u_right)`` (k, 2) of segment pairs the disparity check dropped that may mark the free edge
    ``edge`` of the fitted wall: lines a boundary may be moved onto (:func:`search_boundary`), never features.

    A wall's occluding end is where block matching fails: the window straddles the depth step, and on a plain
    surface (a whiteboard, a partition) no pixel near the end has texture enough to pass the left-right check, so
    the pair of the end's own lines is dropped for want of support (Fig 6) while the region's border stops a window
    or so inside. The boundary was then moved onto the last line the check kept, a feature inside the end (office,
    a whiteboard 0.8 m in front of its wall: its end found on a drawn line 5 cm in, every landmark modelled from it
    3–5 cm off). Such a pair is taken when it lies on the wall (``pairs``: :func:`on_wall_pairs`) and the disparity
    image shows what a free edge has beyond it: something *farther* (the map's depth step). Outward of the line,
    from half a window on and past the strip the step hides from the right camera, at least a third of its rows
    must hold a disparity, and in most of those the first one met must lie more than ``min_step_px`` below the
    pair's own. A line beside a hidden end (a door frame's strip just inside an end that a nearer wall hides,
    whose pixels beyond are unmatched or nearer) shows nothing farther and is not taken. ``box`` ``(rows, cols)``:
    read only there (the plane's band box, :meth:`~stablemarks.planes.PlanePrediction.box`, which a front end that
    computes disparity in regions always computes: the decision is then the same as with dense disparity).
    """
    none = np.zeros((0, 2))
    if len(pairs) == 0:
        return none
    inner = float(_inner_columns(camera, fit.X, fit.plane, edge)[0])
    e = fit.prediction.edges[edge]
    outward = -1 if e.u[0] < inner else 1
    H, W = disparity_left.shape
    (r_lo, r_hi), (c_lo, c_hi) = (0, H), (0, W)
    if box is not None:
        r_lo, r_hi, _ = box[0].indices(H)
        c_lo, c_hi, _ = box[1].indices(W)
    ul, ur = np.asarray(pairs.u_left, dtype=float), np.asarray(pairs.u_right, dtype=float)
    d = ul - ur
    # each pair's threshold in the disparity image's own type: NumPy compares a float32 image with a Python float in
    # float32 (the float rounded to it), and so does the kernel
    below = np.asarray(d - min_step_px, dtype=disparity_left.dtype)
    keep = _edge_lines_kept(disparity_left, ul, d, np.asarray(pairs.v_top, dtype=float),
                            np.asarray(pairs.v_bottom, dtype=float), below, int(outward), int(window_px // 2),
                            int(window_px), r_lo, r_hi, c_lo, c_hi)
    return np.stack([ul[keep], ur[keep]], axis=-1).reshape(-1, 2)


@njit(cache=True)
def _edge_lines_kept(disp, ul, d, v_top, v_bottom, below, outward, half, window, r_lo, r_hi, c_lo, c_hi
                     ):  # pragma: no cover - numba
    """:func:`edge_lines`' test of each pair (the former per-pair array code, ~0.3 ms for a wall's few pairs): its
    sample columns ``rint(u_l + outward · o)`` for ``o`` from ``half + 1`` to ``half + 1 + ceil(d) + window`` inside
    ``[c_lo, c_hi)``, its rows ``ceil(v_top) … floor(v_bottom)`` inside ``[r_lo, r_hi)``; at least 5 rows and a
    column, at least a third of the rows holding a finite disparity, and in more than half of those the first one
    met outward below ``below`` (the pair's disparity less the step, in the image's type). Returns the indices of
    the pairs kept, in order."""
    n = ul.shape[0]
    keep = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        o0 = half + 1
        o1 = half + 2 + int(np.ceil(d[i])) + window  # offsets o0 … o1 − 1
        cols = np.empty(max(0, o1 - o0), dtype=np.int64)
        n_cols = 0
        for o in range(o0, o1):
            c = int(np.rint(ul[i] + float(outward * o)))
            if c >= c_lo and c < c_hi:
                cols[n_cols] = c
                n_cols += 1
        v0 = max(r_lo, int(np.ceil(v_top[i])))
        v1 = min(r_hi, int(np.floor(v_bottom[i])) + 1)
        n_rows = max(0, v1 - v0)
        if n_cols == 0 or n_rows < 5:
            continue
        n_held = 0
        n_below = 0
        for v in range(v0, v1):
            for q in range(n_cols):
                x = disp[v, cols[q]]
                if np.isfinite(x):
                    n_held += 1
                    if x < below[i]:
                        n_below += 1
                    break
        if n_held < n_rows / 3:
            continue
        if n_below > 0.5 * n_held:
            keep[m] = i
            m += 1
    return keep[:m].copy()


def _edge_search(camera: StereoCamera, fit: PlaneFit, edge: str, disparity_right, members_u, config: LandmarkConfig,
                 plane_config: PlaneConfig, window_px: float, valid_columns, world_map: Map | None, border_sigma_px,
                 disparity_range, w_sad: float, inner: dict | None = None) -> tuple[Boundary | bool | None, list]:
    """:func:`landmarks_on_plane`'s search of one free edge: whether it is searched and what is found, ``(found,
    rejected)``: ``found`` None when the edge is not searched, False when searched and not found, else the
    :func:`search_boundary` boundary; ``rejected`` the reasons (with no boundary) it was not searched for.
    ``inner``: a dict of the edges' :func:`_inner_columns` (by edge) to take them from and add them to."""
    e = fit.prediction.edges[edge]
    u_l, u_r = e.u.tolist()
    if not (math.isfinite(u_l) and math.isfinite(u_r)):  # the edge is behind the camera
        return None, []
    window_l = e.window(0, config.search_sigma)
    lo, hi = window_l
    if hi < 0 or lo > camera.width - 1:
        return None, []
    windows = [window_l, e.window(1, config.search_sigma)]
    if valid_columns is not None and any(
        not (vc[0] + 1 < w[0] and w[1] < vc[1] - 1) for w, vc in zip(windows, valid_columns, strict=True)
    ):
        return None, []
    d_edge = None  # the wall's predicted disparity and its σ at the edge's left column, when known
    if disparity_range is not None:
        d, sd = d_edge = fit.prediction.disparity_at(e.u[0])
        d_lo, d_hi = float(d - config.search_sigma * sd), float(d + config.search_sigma * sd)
        if d_hi > disparity_range[1] or d_lo < disparity_range[0]:
            return None, [(None, f"plane {fit.plane.label!r}: the wall's disparity at its free edge {edge} may "
                                 f"be {d_lo:.0f}–{d_hi:.0f} px, beyond the {disparity_range[0]:g}–"
                                 f"{disparity_range[1]:g} px block matching searches (sad.min_disparity, "
                                 "sad.num_disparities): not searched")]
    incidence = edge_incidence(camera, fit.X, fit.plane, edge)
    if incidence > math.radians(config.max_incidence_deg):
        # the limit of the lines modelled from a boundary holds for the boundary too: its column error is
        # stretched along the wall as much, and every landmark placed from it inherits that error (a warehouse
        # aisle: an end seen at 72° placed its wall's landmarks 12–17 cm off, with σ of a few cm)
        return None, [(None, f"plane {fit.plane.label!r}: its free edge {edge} is seen "
                             f"{np.degrees(incidence):.0f}° from the wall's normal (more than "
                             f"landmarks.max_incidence_deg, {config.max_incidence_deg:g}°): not searched")]
    if world_map is not None:
        if edge_occluded(camera, fit.X, world_map, fit.plane, edge):
            return None, []
    # what the depth step, the gap and the search each computed of the edge: its inner columns and the camera's frame
    inner = {} if inner is None else inner
    if edge not in inner:
        inner[edge] = _inner_columns(camera, fit.X, fit.plane, edge)
    u_inner = inner[edge]
    frame = camera._frame(fit.X)
    if world_map is not None:
        step = _edge_depth_step(camera, fit.X, world_map, fit.plane, edge, window_px / 2 + 1, float(u_inner[0]),
                                frame)
        if abs(step) < config.min_edge_step_sigma * plane_config.sigma_nu(camera):
            return None, []
    bridge = None
    if world_map is not None:
        # a hole is followed across up to the whole window, but never across the gap to another wall of the
        # map that would continue the region (less one window: each side's border fattens by half of it)
        span = int(np.ceil(max(w_[1] - w_[0] for w_ in windows)))
        gap = _other_wall_gap(camera, fit, world_map, edge, float(u_inner[0]), frame, window_l, d_edge)
        bridge = span if not np.isfinite(gap) else max(int(w_sad // 2), min(span, int(gap - w_sad)))
    b = _search_boundary(camera, fit, edge, disparity_right, members_u, config, plane_config, window_px,
                         border_sigma_px, bridge, u_inner)
    return (False if b is None else b), []


def _boundary_checks(camera: StereoCamera, fit: PlaneFit, b: Boundary, config: LandmarkConfig, window_px: float,
                     cov_X, disparity_left, inner: dict | None = None) -> tuple[str, bool]:
    """Why :func:`landmarks_on_plane` does not use the boundary ``b`` it found ("" when it does), and whether that
    is because it is the silhouette of something nearer (the wall's end hidden) rather than too far from the map's
    edge for the pose. ``inner``: as :func:`_edge_search`'s."""
    edge = b.edge
    inner = {} if inner is None else inner
    if disparity_left is not None and config.nearer_fraction < 1.0 and edge not in inner:
        inner[edge] = _inner_columns(camera, fit.X, fit.plane, edge)
    if disparity_left is not None and config.nearer_fraction < 1.0 and \
            _occluded_boundary(fit, disparity_left, b, window_px, config.nearer_fraction, float(inner[edge][0])):
        return (f"plane {fit.plane.label!r}: the boundary found at {edge} is the silhouette of "
                "something nearer standing in front of the wall, not its end: not used"), True
    if cov_X is not None:
        off, sigma = boundary_disagreement(b, fit.plane, fit.X, cov_X)
        if abs(off) > config.boundary_gate_sigma * sigma:
            return (f"plane {fit.plane.label!r}: the boundary found at {edge} is {100 * off:+.1f} cm "
                    f"along the wall from the map's free edge (σ {100 * sigma:.1f} cm): not used"), False
    return "", False


def nearer_silhouettes(camera: StereoCamera, X, cov_X, world_map: Map, plane, min_offset: float = 0.1,
                       max_step_px: float = np.inf) -> list[tuple[int, float, float, tuple[float, float]]]:
    """The image columns where the ends of the map's other walls that stand in front of ``plane`` (on the
    camera's side, more than ``min_offset`` metres from it: not a board on it; nearer by at most ``max_step_px``
    of disparity, the steps a disparity test cannot resolve: a screen 1 m in front of a wall at 11 m, 0.6 px) are
    seen against it: ``(image, u, σ_u, z)`` per end and image, ``σ_u`` from the pose covariance (Eq 3's Jacobian)
    [px], ``z`` the heights the other wall spans [m].

    The other walls' ends and their offsets from ``plane`` do not depend on the pose: they are taken from the map
    (:func:`_wall_ends`, made once per map and wall), the ends between neither camera and the wall (most ends of a
    map) are told apart in one array test (the same products and comparisons as on each end's Python floats), and
    the rest are projected together (:meth:`~stablemarks.geometry.StereoCamera.project_columns` of a few points at
    a time: each point's numbers as projected alone). Looping over every end of a large map cost up to ~0.6 ms."""
    out = []
    fb = camera.f * camera.baseline
    centres = camera.optical_centres(X)
    offsets = [float(plane.offset(O)) for O in centres]
    walls, ends, oE_all = _wall_ends(world_map, plane)
    if not len(walls):
        return out
    # not between either camera and the wall: no projection needed (the array test's products and comparisons, on
    # the ends' Python floats)
    todo = [i for i, oE in enumerate(oE_all.tolist())
            if not all((oO * oE <= 0) or (abs(oE) < min_offset) or (abs(oE) >= abs(oO)) for oO in offsets)]
    for start in range(0, len(todo), _FEW_ENDS):
        chunk = todo[start : start + _FEW_ENDS]
        uvs, Js, _ = camera.project_columns(X, ends[chunk], jacobians=True)
        for q, i in enumerate(chunk):
            w, E, oE = walls[i // 2], ends[i], float(oE_all[i])
            uv, J = uvs[q], Js[q].copy()  # a fresh (2, 3) array, as the projection of the one end gave it
            for img in (0, 1):
                O = centres[img]
                oO = offsets[img]
                if not np.isfinite(uv[img]) or oO * oE <= 0 or abs(oE) < min_offset or abs(oE) >= abs(oO):
                    continue  # not in front of the camera, or not between the camera and the wall
                W = O + oO / (oO - oE) * (E - O)  # where the sight line past the end meets the wall
                if fb / np.hypot(*(E - O)) - fb / np.hypot(*(W - O)) > max_step_px:
                    continue
                out.append((img, float(uv[img]), float(np.sqrt(max(J[img] @ cov_X @ J[img], 0.0))), tuple(w.z)))
    return out


_FEW_ENDS = 8
"""Ends projected together, in one :meth:`~stablemarks.geometry.StereoCamera.project_columns` call, by
:func:`nearer_silhouettes`."""


def _wall_ends(world_map: Map, plane) -> tuple[list, np.ndarray, np.ndarray]:
    """The map's walls other than ``plane`` (in map order), their ends (2K, 2) (``P1``, ``P2`` of each, in order:
    rows ``2k``, ``2k + 1`` of wall ``k``) and the ends' offsets from ``plane`` (2K,) (``float(plane.offset(E))`` of
    each end), made once per map and wall (for ``plane`` itself; another object of the same id is computed
    afresh)."""
    cache = world_map.__dict__.setdefault("_wall_ends", {})
    hit = cache.get(plane.id)
    if hit is not None and hit[0] is plane:
        return hit[1]
    walls = [w for w in world_map if w.id != plane.id]
    ends = np.array([E for w in walls for E in (w.P1, w.P2)], dtype=float).reshape(-1, 2)
    oE = np.array([float(plane.offset(E)) for w in walls for E in (w.P1, w.P2)], dtype=float)
    for a in (ends, oE):
        a.setflags(write=False)
    cache[plane.id] = (plane, (walls, ends, oE))
    return walls, ends, oE


def _at_silhouette(camera: StereoCamera, c: Candidate, silhouettes, k: float) -> bool:
    """Whether candidate ``c``'s line lies within ``k`` σ (the silhouette's column from the pose and the line
    noise) of a nearer wall's end seen against its wall, in either image, on rows that wall covers."""
    for img, u, sigma, z in silhouettes:
        if c.z_high < z[0] or c.z_low > z[1]:
            continue
        if abs((c.u_left, c.u_right)[img] - u) <= k * np.hypot(sigma, camera.sigma_img):
            return True
    return False


def beside_nearer(fit: PlaneFit, disparity_left: np.ndarray, c: Candidate, slope: float, window_px: float,
                  fraction: float) -> int:
    """Which side of candidate ``c``'s left line (-1 left, +1 right, 0 neither) something nearer than its wall
    stands on: over the line's rows, the left disparity from half a window to one window beyond the line
    (block matching carries a nearer surface's disparity up to half a window over a depth edge), read only
    inside the plane's band box (the pixels :func:`select_landmarks` computes), is above the wall's band
    (:meth:`~stablemarks.planes.PlanePrediction.disparity_at`, ``gate`` σ and 1 px) on most of each row's
    samples, on at least ``fraction`` of the rows that hold a disparity there (and at least a third of all).
    One candidate of :func:`beside_nearer_sides`."""
    return int(beside_nearer_sides(fit, disparity_left, np.array([c.u_left]), np.array([c.v_top]),
                                   np.array([c.v_bottom]), np.array([slope]), window_px, fraction)[0])


def occluded_boundary(camera: StereoCamera, fit: PlaneFit, disparity_left: np.ndarray, b: Boundary,
                      window_px: float, fraction: float) -> bool:
    """Whether boundary ``b`` is the silhouette of something standing in front of its wall rather than the
    wall's end: beyond it (outward, away from the wall), over the wall's rows at that column, the left disparity
    is nearer than the wall's band as :func:`beside_nearer` reads it. A free edge has something *farther* beyond
    it (the map's depth step, :func:`edge_depth_step`); a nearer surface there hides the end, and the planar
    region stops at the occluder's side (the office: a pole 0.8 m in front of the white board's end, whose
    region ended 16–34 px inside the hidden edge, 6–16 cm along the wall)."""
    return _occluded_boundary(fit, disparity_left, b, window_px, fraction,
                              float(_inner_columns(camera, fit.X, fit.plane, b.edge)[0]))


def _occluded_boundary(fit: PlaneFit, disparity_left: np.ndarray, b: Boundary, window_px: float, fraction: float,
                       inner: float) -> bool:
    """:func:`occluded_boundary` with the left column ``inner`` of the edge's :func:`_inner_columns` known."""
    pred = fit.prediction
    u = float(b.u[0])
    outward = -1 if u < inner else 1
    v_top, v_bottom = pred.interp_two(u, "v_top", "v_bottom")  # np.interp's values at u
    return int(beside_nearer_sides(fit, disparity_left, [u], [float(v_top)], [float(v_bottom)], [0.0], window_px,
                                   fraction, (outward,))[0]) == outward


def beside_nearer_sides(fit: PlaneFit, disparity_left: np.ndarray, u_left, v_top, v_bottom, slope,
                        window_px: float, fraction: float, sides: tuple[int, ...] = (-1, 1)) -> np.ndarray:
    """:func:`beside_nearer` of several lines at once: (n,) int sides of the lines with left columns ``u_left``
    (at mid-height), rows ``v_top`` … ``v_bottom`` and slopes ``slope`` (n,) [px per row], looking on ``sides``
    in that order (:func:`occluded_boundary` looks on one). One numba pass over all the lines
    (:func:`_beside_nearer_sides`): the former per-line NumPy expressions cost ~0.2 ms a line in small-array
    overhead, a frame's selected lines ~2 ms; the same samples, arithmetic and decisions."""
    pred = fit.prediction
    rows_box, cols_box = pred.box(disparity_left.shape[0])
    return _beside_nearer_sides(
        disparity_left, rows_box.start, rows_box.stop, cols_box.start, cols_box.stop,
        np.asarray(u_left, dtype=np.float64), np.asarray(v_top, dtype=np.float64),
        np.asarray(v_bottom, dtype=np.float64), np.asarray(slope, dtype=np.float64),
        int(window_px // 2) + 1, int(window_px) + 2, pred._columns_float,
        np.asarray(pred.d, dtype=np.float64), np.asarray(pred.sigma_d, dtype=np.float64), float(pred.gate),
        float(fraction), np.asarray(sides, dtype=np.int64))


@njit(cache=True)
def _interp(x, xp, fp):  # pragma: no cover - numba
    """``np.interp(x, xp, fp)`` of one number, the same operations as NumPy's C loop (outside ``xp`` the end
    values; at a node its value; else the slope ``(fp[j+1] − fp[j]) / (xp[j+1] − xp[j])`` times ``x − xp[j]``
    plus ``fp[j]``, with NumPy's fallbacks where that is NaN)."""
    n = len(xp)
    if np.isnan(x):
        return x
    if x < xp[0]:
        return fp[0]
    if x > xp[n - 1]:
        return fp[n - 1]
    if x == xp[n - 1] or n == 1:
        return fp[n - 1]
    lo, hi = 0, n - 1  # xp[lo] <= x < xp[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    j = lo
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if np.isnan(y):
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(y) and fp[j] == fp[j + 1]:
            y = fp[j]
    return y


@njit(cache=True)
def _beside_nearer_sides(disp, r0, r1, c0, c1, u_left, v_top, v_bottom, slope, o0, o1, columns, d, sigma_d, gate,
                         fraction, sides):  # pragma: no cover - numba
    """:func:`beside_nearer_sides` in the band box ``[r0, r1) × [c0, c1)`` of the left disparity ``disp``, the
    samples at offsets ``o0 … o1 − 1`` on each of ``sides`` of each line (in that order). Per line and side, as the
    former array code: each row's sample columns ``rint(u_row ± offset)``, ``u_row = u_left + slope (v − mid)``;
    a sample holds a disparity when inside the box and finite, is nearer when above ``d_wall + gate σ + 1`` at
    its column (computed once per column of the box, when a sample there first holds a disparity: the lines'
    samples reach a few dozen of the box's columns)."""
    limit = np.full(max(0, c1 - c0), np.nan)
    n = len(u_left)
    out = np.zeros(n, dtype=np.int64)
    for i in range(n):
        v0 = max(int(np.ceil(v_top[i])), r0)
        v1 = min(int(np.floor(v_bottom[i])), r1 - 1)
        if v1 - v0 < 4:
            continue
        n_rows = v1 - v0 + 1
        mid = 0.5 * (v_top[i] + v_bottom[i])
        for side in sides:
            n_held = 0
            n_nearer = 0
            for v in range(v0, v1 + 1):
                u_row = u_left[i] + slope[i] * (float(v) - mid)
                n_valid = 0
                n_near = 0
                for off in range(o0, o1):
                    col = int(np.rint(u_row + float(side * off)))
                    if col < c0 or col >= c1:
                        continue
                    x = float(disp[v, col])
                    if not np.isfinite(x):
                        continue
                    n_valid += 1
                    lim = limit[col - c0]
                    if np.isnan(lim):
                        fc = float(col)
                        lim = limit[col - c0] = _interp(fc, columns, d) + gate * _interp(fc, columns, sigma_d) + 1.0
                    if x > lim:
                        n_near += 1
                if n_valid > 0:
                    n_held += 1
                    if 2 * n_near > n_valid:
                        n_nearer += 1
            if n_held >= n_rows / 3 and n_nearer >= fraction * n_held:
                out[i] = side
                break
    return out


def nearer_than_fit(camera: StereoCamera, fit: PlaneFit, disparity_left: np.ndarray, u_left, v_top, v_bottom, slope,
                    window_px: float, sigma_nu: float) -> np.ndarray:
    """(n,) how much nearer than the *fitted* wall something stands beside each line, as a score in standard errors
    (the larger of the two sides; NaN where too few rows hold a disparity on either side).

    The samples are :func:`beside_nearer`'s (half a window to one window beyond the line, rows ``v_top … v_bottom``
    along the line's ``slope``), but wherever the frame holds a disparity, not only inside the plane's band box: the
    nearer thing beside a line at the band's edge is often another wall, whose own region computed it (the office:
    a line of the east wall beside the end of a partition 1.8 m nearer). Each sample's disparity less the fitted
    wall's at its column (the ray meeting the line ``o = a + b (s − s0)`` seen from ``fit.X``): per row their
    median, per side the median ``m`` of the rows (every fifth of a window's rows). The score is ``m`` over the
    standard error of that median, ``1.2533 σ / sqrt(n_rows / window)`` (a SAD window's rows share their errors),
    ``σ`` the larger of ``sigma_nu`` and the rows' own spread (1.4826 MAD), combined with the fitted wall's σ of
    disparity at the line (from ``fit.cov_R``)."""
    u_left = np.asarray(u_left, dtype=np.float64)
    n = len(u_left)
    if n == 0:
        return np.zeros(0)
    plane = fit.plane
    cam = camera.camera_pose(np.asarray(fit.X, dtype=float))
    cth, sth = math.cos(cam.theta), math.sin(cam.theta)  # forward (cth, sth), right (sth, −cth)
    c_s, c_o = float(plane.along(cam.translation)), float(plane.offset(cam.translation))
    cov = np.asarray(fit.cov_R, dtype=float)
    z = _nearer_than_fit(
        disparity_left, u_left,
        np.asarray(v_top, dtype=np.float64), np.asarray(v_bottom, dtype=np.float64),
        np.asarray(slope, dtype=np.float64), int(window_px // 2) + 1, int(window_px) + 2,
        float(camera.cu), float(camera.f), cth, sth, sth, -cth, float(plane.direction[0]),
        float(plane.direction[1]), float(plane.normal[0]), float(plane.normal[1]), c_s, c_o, float(fit.a),
        float(fit.b), float(fit.s0), float(camera.f * camera.baseline), float(sigma_nu), float(window_px),
        float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1]))
    return z


@njit(cache=True)
def _small_median(vals, k):  # pragma: no cover - numba
    """``np.median(vals[:k])`` of a few numbers, sorting them in place (insertion sort, no allocation)."""
    for i in range(1, k):
        x = vals[i]
        j = i - 1
        while j >= 0 and vals[j] > x:
            vals[j + 1] = vals[j]
            j -= 1
        vals[j + 1] = x
    h = k // 2
    return vals[h] if k % 2 else 0.5 * (vals[h - 1] + vals[h])


@njit(cache=True)
def _nearer_than_fit(disp, u_left, v_top, v_bottom, slope, o0, o1, cu, f, fx, fy, rx, ry, dx, dy, nx, ny, c_s, c_o, a,
                     b, s0, fb, sigma_nu, window, caa, cab, cbb):  # pragma: no cover - numba
    """:func:`nearer_than_fit`'s scores, one pass over the lines' samples (the fitted wall's σ of disparity at each
    line's column from its covariance ``[[caa, cab], [cab, cbb]]`` of ``(a, b)``); the fitted wall's disparity
    computed once per column, when a sample there first holds a disparity. Every ``step``-th row (a fifth of a
    window: the rows of one window share their errors, so the median loses next to nothing), counted as such in
    the error."""
    n = len(u_left)
    H, W = disp.shape
    out = np.full(n, np.nan)
    vals = np.empty(o1 - o0)
    d_fit = np.full(W, np.nan)
    step = max(1, int(window) // 5)
    for i in range(n):
        v0 = max(int(np.ceil(v_top[i])), 0)
        v1 = min(int(np.floor(v_bottom[i])), H - 1)
        if v1 - v0 < 4:
            continue
        n_rows = v1 - v0 + 1
        mid = 0.5 * (v_top[i] + v_bottom[i])
        rows = np.empty(n_rows)
        # the fitted wall's disparity error at the line's column: ∂d/∂(a, b) through the depth Z there
        xn = (u_left[i] - cu) / f
        wx, wy = fx + xn * rx, fy + xn * ry
        r_s, r_o = wx * dx + wy * dy, wx * nx + wy * ny
        den = r_o - b * r_s
        depth = (a + b * (c_s - s0) - c_o) / den
        ja = -fb / depth**2 / den
        jb = ja * (c_s - s0 + depth * r_s)
        var_fit = max(0.0, ja * ja * caa + 2.0 * ja * jb * cab + jb * jb * cbb)
        for side in (-1, 1):
            m_rows = 0
            for v in range(v0, v1 + 1, step):
                u_row = u_left[i] + slope[i] * (float(v) - mid)
                k = 0
                for off in range(o0, o1):
                    col = int(np.rint(u_row + float(side * off)))
                    if col < 0 or col >= W:
                        continue
                    x = float(disp[v, col])
                    if not np.isfinite(x):
                        continue
                    w = d_fit[col]
                    if np.isnan(w):
                        xn = (float(col) - cu) / f
                        wx, wy = fx + xn * rx, fy + xn * ry
                        r_s, r_o = wx * dx + wy * dy, wx * nx + wy * ny
                        depth = (a + b * (c_s - s0) - c_o) / (r_o - b * r_s)
                        w = d_fit[col] = fb / depth if depth > 0 else np.inf
                    if not np.isfinite(w):
                        continue
                    vals[k] = x - w
                    k += 1
                if k > 0:
                    rows[m_rows] = _small_median(vals, k)
                    m_rows += 1
            if m_rows < 5:  # the standard error below counts the rows that hold a disparity
                continue
            med = np.median(rows[:m_rows])
            mad = np.median(np.abs(rows[:m_rows] - med))
            spread = max(sigma_nu, 1.4826 * mad)
            se2 = (1.2533 * spread) ** 2 / max(1.0, m_rows * step / window) + var_fit
            score = med / np.sqrt(se2)
            if np.isnan(out[i]) or score > out[i]:
                out[i] = score
    return out


SLOPE_GATE_CHI2 = 10.83
"""χ²₁(0.999): a fitted wall's slope alone beyond this is turned from the map (see :func:`fit_disagreements`)."""


def seen_wall_jacobian(camera: StereoCamera, fit: PlaneFit) -> np.ndarray:
    """``J = ∂(a, b)/∂X`` (2, 3): how an error of the pose moves the map's wall as the camera sees it placed with
    the belief ``fit.X`` (offset ``a`` at ``fit.s0`` [m] and slope ``b`` of the line in the wall's frame), by
    central differences: the wall carried into the camera frame by one pose and back out by another.

    On Python floats (two points, six poses: NumPy's small-array overhead was ~0.14 ms a call); the same
    operations as the array expressions it replaced, the wall frame's dot products summed left to right."""
    plane, X = fit.plane, np.asarray(fit.X, dtype=float)
    p1x, p1y = (float(v) for v in plane.P1)
    tx, ty = (float(v) for v in plane.direction)
    nx, ny = (float(v) for v in plane.normal)
    s0 = float(fit.s0)
    cx, cy, psi, cs, sn = camera._frame(X)
    q = []
    for s in (s0 - 1.0, s0 + 1.0):  # two points of the wall, in the camera frame
        dx, dy = (p1x + s * tx) - cx, (p1y + s * ty) - cy
        q.append((cs * dx + sn * dy, -sn * dx + cs * dy))

    def seen(Xp):
        x, y, _, c, s_ = camera._frame(Xp)
        o, t = [], []
        for q0, q1 in q:
            rx, ry = (x + (c * q0 - s_ * q1)) - p1x, (y + (s_ * q0 + c * q1)) - p1y
            o.append(rx * nx + ry * ny)
            t.append(rx * tx + ry * ty)
        b = (o[1] - o[0]) / (t[1] - t[0])
        return o[0] + b * (s0 - t[0]), b

    J = np.empty((2, 3))
    for i, h in enumerate((1e-4, 1e-4, 1e-5)):
        e = np.zeros(3)
        e[i] = h
        (ap, bp), (am, bm) = seen(X + e), seen(X - e)
        J[0, i] = (ap - am) / (2 * h)
        J[1, i] = (bp - bm) / (2 * h)
    return J


def fit_disagreements(camera: StereoCamera, fit: PlaneFit, cov_X, cov_map=None) -> tuple[float, float]:
    """Mahalanobis² of the fitted line ``(a, b)`` against the map's wall (``(0, 0)``) with covariance
    ``J Σ_X Jᵀ + Σ_R`` (:func:`seen_wall_jacobian`), and of ``b`` alone (1 dof): a wall turned from the map (a
    wrong pan turns them all), as opposed to one shifted (a slip or a kidnap moves them). ``cov_map`` (2, 2):
    the map wall's own uncertainty in ``(a, b)`` (default none)."""
    J = seen_wall_jacobian(camera, fit)
    S = J @ np.asarray(cov_X, dtype=float) @ J.T + fit.cov_R
    if cov_map is not None:
        S = S + np.asarray(cov_map, dtype=float)
    slope = float(fit.b**2 / S[1, 1]) if S[1, 1] > 0 else 0.0
    r = np.array([fit.a, fit.b])
    try:
        return float(r @ np.linalg.solve(S, r)), slope
    except np.linalg.LinAlgError:
        return 0.0, slope


def common_turn(camera: StereoCamera, fits, cov_X, cov_map=None) -> tuple[float, float, float, float]:
    """One rotation ``δ`` [rad] shared by the slopes of the walls fitted in one frame, and its Mahalanobis² (1 dof)
    against none.

    Only a rotation turns a wall as the camera sees it (a slip or a kidnap moves the robot, which shifts the walls
    but leaves their slopes): a head pan off by ``δ`` turns every wall in view by ``δ``, in the same sense. The slopes
    ``b`` of the fits are, without a turn, ``N(0, S)`` with ``S = J_b Σ_X J_bᵀ + diag(σ_b²)`` (each fit's own slope
    variance and the map's angle accuracy, ``cov_map`` (2, 2) as in :func:`fit_disagreements`; the pose's share is
    common to all walls); the turn's direction is ``g = ∂b/∂θ`` (a turn of the head turns them like a turn of the
    robot). Generalised least squares: ``δ = gᵀS⁻¹b / gᵀS⁻¹g``, Mahalanobis² ``(gᵀS⁻¹b)² / gᵀS⁻¹g``. Each wall
    alone is :func:`fit_disagreements`' slope test; several walls that each pass it can still share a turn far
    beyond the heading's uncertainty. Returns ``(δ, Mahalanobis², spread, var_own)``: ``spread`` the Mahalanobis²
    of the slopes about the shared turn (``n − 1`` dof; walls turned different ways are not one turn) and
    ``var_own`` the shared turn's variance from the fits alone (without the pose's share); ``(0, 0, 0, ∞)``
    without fits."""
    fits = list(fits)
    if not fits:
        return 0.0, 0.0, 0.0, np.inf
    Jb = np.array([seen_wall_jacobian(camera, f)[1] for f in fits])
    var_map = 0.0 if cov_map is None else float(np.asarray(cov_map, dtype=float)[1, 1])
    own = np.array([float(f.cov_R[1, 1]) + var_map for f in fits])
    S = Jb @ np.asarray(cov_X, dtype=float) @ Jb.T + np.diag(own)
    b = np.array([float(f.b) for f in fits])
    g = Jb[:, 2]
    try:
        Sg = np.linalg.solve(S, g)
    except np.linalg.LinAlgError:
        return 0.0, 0.0, 0.0, np.inf
    info = float(g @ Sg)
    if not info > 0:
        return 0.0, 0.0, 0.0, np.inf
    score = float(Sg @ b)
    d = score / info
    r = b - g * d
    try:
        spread = float(r @ np.linalg.solve(S, r))
    except np.linalg.LinAlgError:
        spread = np.inf
    var_own = 1.0 / float(np.sum(g**2 / own))
    return d, score**2 / info, spread, var_own


def boundary_disagreement(b: Boundary, plane, X, cov_X) -> tuple[float, float]:
    """How far [m] boundary ``b`` (found from the mean pose ``X``) lies along the wall from the map's free edge,
    inward positive, and the σ of that difference [m]: the boundary's own ``σ_along`` and the pose covariance
    ``cov_X`` (3, 3) carried through the rigid placement ``P = R(θ) p + (x, y)``, projected on the wall."""
    t = b.inward
    off = float((b.P - plane.edge(b.edge)) @ t)
    (p0, p1), (x0, x1, _) = np.asarray(b.P, dtype=float).tolist(), np.asarray(X, dtype=float).tolist()
    J = np.array([[1.0, 0.0, -(p1 - x1)], [0.0, 1.0, p0 - x0]])  # ∂P/∂(x, y, θ)
    Jt = t @ J
    return off, float(np.sqrt(b.sigma_along**2 + Jt @ np.asarray(cov_X, dtype=float) @ Jt))


def boundaries_apart(models: list[PlaneLandmarks], config: LandmarkConfig) -> dict[tuple[str, str], str]:
    """Boundaries of different walls found in one frame whose distance disagrees with the map's: ``{(plane id,
    edge): why}`` for each boundary not to be used.

    The distance between two points seen in one frame does not depend on the pose, and the map fixes the distance
    between two free edges: two boundaries whose distance differs from their edges' by more than
    ``boundary_gate_sigma`` σ (their covariances along the line joining them) cannot both be right. Each was
    already checked against the map through the pose (:func:`boundary_disagreement`); both fit it, so the pose
    cannot tell which is wrong, and neither is used (the storeroom's doorway, after a blind stretch with the
    position 17 cm off: its two jambs found 18 cm out either way, one on the wall beyond the door, and the
    landmarks modelled from them held the pose 10 cm off with NEES 143). The two ends of one wall are checked
    the same way in :func:`landmarks_on_plane`."""
    found = [(m.fit.plane, b) for m in models for b in m.boundaries]
    out: dict[tuple[str, str], str] = {}
    for i, (plane_i, bi) in enumerate(found):
        for plane_j, bj in found[i + 1:]:
            if plane_i.id == plane_j.id:
                continue
            d = bj.P - bi.P
            d_map = plane_j.edge(bj.edge) - plane_i.edge(bi.edge)
            n, n_map = float(np.hypot(*d)), float(np.hypot(*d_map))
            u = d / n if n > 1e-9 else (d_map / n_map if n_map > 1e-9 else np.array([1.0, 0.0]))
            sigma = float(np.sqrt(u @ (bi.cov + bj.cov) @ u))
            if abs(n - n_map) > config.boundary_gate_sigma * sigma:
                why = (f"the boundaries found at {plane_i.label!r} {bi.edge} and {plane_j.label!r} {bj.edge} are "
                       f"{100 * n:.1f} cm apart, the map's free edges {100 * n_map:.1f} cm (σ {100 * sigma:.1f} cm): "
                       "the pose cannot tell which is wrong, so both are not used")
                for plane, b in ((plane_i, bi), (plane_j, bj)):
                    out.setdefault((plane.id, b.edge), f"plane {plane.label!r}: {why}")
    return out


def mapped_boundaries(plane, boundaries: list[Boundary], ref: Boundary) -> list[Boundary]:
    """The plane's ends not found in this frame (free or not: where a wall meets another, its edge is a
    boundary too), placed the wall's length from ``ref`` (the map fixes it) with ``ref``'s uncertainty,
    for the near-boundary rule."""
    found = {b.edge for b in boundaries}
    return [_replace_boundary(ref, edge=e, P=ref.P + plane.length * ref.inward, inward=-ref.inward)
            for e in ("p1", "p2") if e not in found]


def _replace_boundary(b: Boundary, **kw) -> Boundary:
    """``dataclasses.replace(b, **kw)`` of a Boundary without its cost (see :func:`_replace`: Boundary has no
    ``__post_init__`` or init-only fields, so the two are the same object)."""
    unknown = kw.keys() - _BOUNDARY_FIELDS
    if unknown:
        raise TypeError(f"Boundary has no field {sorted(unknown)[0]!r}")
    new = object.__new__(Boundary)
    new.__dict__.update(b.__dict__)
    new.__dict__.update(kw)
    return new


def wall_columns(camera: StereoCamera, fit: PlaneFit, search_sigma: float) -> tuple[float, float]:
    """Left-image columns the wall can occupy: from the outer side of one end's search window to the other's;
    unbounded beyond an end that is behind the camera."""
    lo, hi = -np.inf, np.inf
    for name, e in fit.prediction.edges.items():
        u_l, u_r = e.u.tolist()
        if not (math.isfinite(u_l) and math.isfinite(u_r)):
            continue
        w_lo, w_hi = e.window(0, search_sigma)
        if _inner_columns(camera, fit.X, fit.plane, name, 0.1)[0] >= u_l:  # the wall lies right of this end
            lo = w_lo if lo == -np.inf else min(lo, w_lo)
        else:
            hi = w_hi if hi == np.inf else max(hi, w_hi)
    return float(lo), float(hi)


def _inner_columns(camera: StereoCamera, X, plane, edge: str, depth: float = 0.3) -> np.ndarray:
    """(2,) image columns of a point ``depth`` metres (at most half the wall) inside the wall from ``edge``:
    which way the wall lies from its end in each image."""
    # plane.point_at of one distance on Python floats (the same products and sums), projected as one point
    s = float(min(depth, 0.5 * plane.length))
    if edge == "p1":
        (x0, y0), (tx, ty) = plane.P1.tolist(), plane.direction.tolist()
    else:
        (x0, y0), (tx, ty) = plane.P2.tolist(), (-plane.direction).tolist()
    return camera.project_columns(X, np.array([x0 + s * tx, y0 + s * ty]))


def _other_walls(world_map: Map, plane) -> tuple[np.ndarray, list[int]]:
    """The map's walls (K, 2, 2) and the index of ``plane`` among them to leave out (none if not in the map)."""
    walls, exclude, _ = world_map.others(plane.id)
    return walls, exclude


def other_wall_gap(camera: StereoCamera, fit: PlaneFit, world_map: Map, edge: str, search_sigma: float) -> float:
    """Columns [px] from the wall's end ``edge`` to the first column beyond it, in the left image, where another
    wall of the map shows at a disparity inside the plane's band (inf when none does): the planar region could
    run on over that wall (two partitions in a row, the wall beyond a doorway), so a hole in the region as wide
    as the gap between them must not be bridged.

    The other wall is looked for out to twice the search window's outer half: its predicted column shares the
    pose's error with the edge's, so one that projects just beyond the window may lie inside it (a doorway 1 m
    wide seen at 3.7 m with a heading σ of 4.6°: the wall beyond the door predicted 26 px outside the window,
    found 30 px inside it, and the region bridged across the door to its far side). The gap itself is nearly
    free of that error (both ends move together)."""
    return _other_wall_gap(camera, fit, world_map, edge, float(_inner_columns(camera, fit.X, fit.plane, edge)[0]),
                           camera._frame(fit.X), fit.prediction.edges[edge].window(0, search_sigma))


def _other_wall_gap(camera: StereoCamera, fit: PlaneFit, world_map: Map, edge: str, u_i: float, frame, window,
                    d_edge=None) -> float:
    """:func:`other_wall_gap` with the edge's inner left column ``u_i`` (:func:`_inner_columns`), the camera's
    ``frame`` (:meth:`~stablemarks.geometry.StereoCamera._frame` of ``fit.X``), the edge's left search ``window``
    and, when known, the prediction's ``(d, σ_d)`` at the edge's left column. The scanned columns are
    ``np.linspace``'s, made inside the scan (:func:`_wall_gap_scan`)."""
    e = fit.prediction.edges[edge]
    u_e = float(e.u[0])
    if not math.isfinite(u_e + u_i):
        return 0.0
    lo, hi = window
    outer = lo if u_e < u_i else hi
    outer = u_e + 2.0 * (outer - u_e)
    num = max(2, int(abs(outer - u_e)) + 1)
    walls, exclude, kept = world_map.others(fit.plane.id)
    if len(walls) == len(exclude):
        return np.inf
    cx, cy, psi, c, s = frame
    d, sigma = fit.prediction.disparity_at(u_e) if d_edge is None else d_edge
    return float(_wall_gap_scan(u_e, outer, num, float(camera.cu), float(camera.f), c, s, cx, cy, walls, kept,
                                float(np.cos(psi)), float(np.sin(psi)), float(camera.f * camera.baseline), float(d),
                                float(fit.prediction.gate * sigma + 1.0)))


@njit(cache=True, error_model="numpy")
def _wall_gap_scan(start, stop, num, cu, f, c, s, cx, cy, walls, kept, fwd0, fwd1, fb, d_edge,
                   tol):  # pragma: no cover - numba
    """:func:`other_wall_gap`'s columns ``np.linspace(start, stop, num)`` (``num`` >= 2: ``i · step + start`` with
    ``step = (stop − start) / (num − 1)``, ``(i / (num − 1)) · (stop − start) + start`` when that step is 0, the last
    one ``stop``: NumPy's operations) scanned by :func:`_first_wall_in_band`: ``|column − start|`` of the first hit,
    inf when none (the array of columns made here, not by a NumPy call per edge)."""
    cols = np.empty(num)
    div = num - 1
    delta = stop - start
    step = delta / div
    for i in range(num):
        cols[i] = (float(i) / div) * delta + start if step == 0 else float(i) * step + start
    cols[num - 1] = stop
    hit = _first_wall_in_band(cols, cu, f, c, s, cx, cy, walls, kept, fwd0, fwd1, fb, d_edge, tol)
    return abs(cols[hit] - start) if hit >= 0 else np.inf


@njit(cache=True, error_model="numpy")
def _first_wall_in_band(cols, cu, f, c, s, cx, cy, walls, kept, fwd0, fwd1, fb, d_edge, tol):  # pragma: no cover
    """:func:`other_wall_gap`'s scan: the first of the left image's columns ``cols`` (in order from the edge) whose
    ray from the left optical centre ``(cx, cy)`` (heading ``(c, s)``, ``fwd`` its (cos, sin) as NumPy computes
    them) first hits one of the walls ``walls[kept]`` at a disparity within ``tol`` of ``d_edge``; -1 when none.
    Per column what :meth:`~stablemarks.geometry.StereoCamera.column_ray`, :func:`~stablemarks.maps.ray_distances`
    and the depth along the optical axis computed for all of them (the ray's unit direction, the nearest crossing
    beyond 1e-9 m, ``Z = dist · (ray · fwd)``, disparity ``fb / Z`` or 0 where not finite and positive), stopping at
    the first hit: the former array code cast every ray over twice the window (~90 µs an edge). The depth's dot
    product is summed left to right (NumPy's matrix-vector product may fuse its multiply-add: the disparity may
    differ in its last bit, the hit only at an exact tie)."""
    for i in range(cols.shape[0]):
        xn = (cols[i] - cu) / f
        d0 = c + s * xn
        d1 = s - c * xn
        norm = np.sqrt(d0 * d0 + d1 * d1)
        r0 = d0 / norm
        r1 = d1 / norm
        Z = nearest_crossing(cx, cy, r0, r1, walls, kept) * (r0 * fwd0 + r1 * fwd1)
        d = fb / Z if np.isfinite(Z) and Z > 0 else 0.0
        if abs(d - d_edge) <= tol:
            return i
    return -1


def edge_incidence(camera: StereoCamera, X, plane, edge: str) -> float:
    """Angle [rad] between the left camera's viewing ray to the wall's end ``edge`` (from pose ``X``) and the
    wall's normal: 0 seen head-on, π/2 along the wall."""
    cx, cy, *_ = camera._frame(X)
    ray = plane.edge(edge) - np.array([cx, cy])  # optical_centres(X)[0]
    norm = float(np.hypot(ray[0], ray[1]))
    if norm == 0.0:
        return math.pi / 2
    return math.acos(min(1.0, abs(float(ray @ plane.normal)) / norm))


def edge_occluded(camera: StereoCamera, X, world_map: Map, plane, edge: str) -> bool:
    """Whether another wall of the map stands between the left camera and the wall's end ``edge``: the region
    then ends at that wall's edge, not at this one's."""
    walls, _, kept = world_map.others(plane.id)
    cx, cy, *_ = camera._frame(X)  # the left optical centre; segments_block of its one sight line
    ex, ey = plane.edge(edge).tolist()
    return bool(sight_blocked(cx, cy, ex - cx, ey - cy, walls, kept))


def edge_depth_step(camera: StereoCamera, X, world_map: Map, plane, edge: str, offset_px: float) -> float:
    """Disparity [px] the map predicts ``offset_px`` columns beyond a wall's edge in the left image, minus
    the wall's own disparity at the edge (from pose ``X``). Positive: something nearer than the wall lies
    beyond the edge; the wall's negated disparity when no wall of the map is hit (open space)."""
    return _edge_depth_step(camera, X, world_map, plane, edge, offset_px,
                            float(_inner_columns(camera, X, plane, edge)[0]), camera._frame(X))


def _edge_depth_step(camera: StereoCamera, X, world_map: Map, plane, edge: str, offset_px: float, u_i: float,
                     frame) -> float:
    """:func:`edge_depth_step` with the edge's inner left column ``u_i`` (:func:`_inner_columns`) and the camera's
    ``frame`` (:meth:`~stablemarks.geometry.StereoCamera._frame` of ``X``) already known."""
    cx, cy, psi, c, s = frame
    px, py = plane.edge(edge).tolist()
    u_e = float(camera._project_point(px - cx, py - cy, c, s)[0])  # project_columns of the one point
    if not math.isfinite(u_e + u_i):
        return 0.0
    u_out = u_e + (1.0 if u_e > u_i else -1.0 if u_e < u_i else 0.0) * offset_px  # np.sign of a finite difference
    fb = camera.f * camera.baseline
    # to_camera and column_ray of one point / one column on Python floats: the same operations (the ray's norm the
    # square root of its two squares summed, as np.linalg.norm along an axis)
    Z_e = c * (px - cx) + s * (py - cy)
    xn = (u_out - camera.cu) / camera.f
    r0, r1 = c + s * xn, s - c * xn
    norm = math.sqrt(r0 * r0 + r1 * r1)
    ray0, ray1 = r0 / norm, r1 / norm
    walls, _, kept = world_map.others(plane.id)
    dist = nearest_crossing(cx, cy, ray0, ray1, walls, kept)  # ray_distances of the one ray
    # the depth along the optical axis as NumPy's dot product of the two pairs (the camera's heading is psi)
    Z_bg = dist * (np.array([ray0, ray1]) @ np.array([np.cos(psi), np.sin(psi)]))
    return float((fb / Z_bg if np.isfinite(Z_bg) and Z_bg > 0 else 0.0) - fb / Z_e)
