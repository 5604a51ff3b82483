"""The mirror ambiguity of coplanar anchors, handled in the fusion filter (beyond Cao et al.).

Pure core (no rclpy). Three anchors (or more, nearly coplanar) leave two positions that fit their
ranges: the tag and its mirror image across their plane. :mod:`.mirror_test` holds the maths (the
plane, the reflection, the accumulated GNSS log-likelihood ratio); this module applies it to the
filter's state (:class:`.filter_state.FilterState`):

* :func:`mirror_check`: at each GNSS epoch, the evidence of the pseudoranges for the mirror, or the
  installer's side of the plane (``uwb_tag_side_of_anchor_plane``), and the jump to the mirror;
* :func:`side_prior_uwb`: the installer's side without GNSS;
* :func:`mirror_covariance`: the covariance the ambiguity adds to the published position
  (``uwb_mirror_covariance``);
* :func:`side_of_anchor_plane`: the side the state is on (kept by the spoofing response while all GNSS
  is excluded).
"""

from __future__ import annotations

import math

import numpy as np

from .ckf import CubatureKalmanFilter
from .filter_state import FilterFacade
from .fusion_params import FRAME_EARTH
from .input_checks import PreparedEpoch
from .measurement_models import pseudorange_model
from .mirror_test import (
    MIRROR_MAX_RANGE_CHANGE_SIGMA,
    anchor_plane,
    clock_free_chi2,
    householder,
    is_range_ambiguous,
    mirror_wrong_side_probability,
    reflect,
)

_NS = 1_000_000_000


def mirror_check(f: FilterFacade, stamp_ns: int, prep: PreparedEpoch, accepted: np.ndarray,
                 bias_column: np.ndarray | None) -> None:
    """Add the epoch to the mirror test (:mod:`.mirror_test`) and jump to the mirror when the
    GNSS evidence says so (beyond the paper).

    The anchors are those heard within ``uwb_init_window_s`` (the test restarts when that set
    changes); the mirror is the reflection of the tag (antenna plus lever arm) across their
    best-fit plane, tested only if it leaves every range within ``MIRROR_MAX_RANGE_CHANGE_SIGMA``
    range 1-sigmas. The residuals are the raw pseudorange residuals (inter-system biases
    applied, correlated-error states not: the test scales for the correlation itself) of the
    pseudoranges the update accepted. The jump reflects position and velocity and applies the
    same reflection to the error covariance (``P <- T P T^T``, exact for a linear map).
    """
    s = f.state
    p = f.params
    if s.frame != FRAME_EARTH or int(accepted.sum()) < 4:
        return
    window_ns = p.uwb_init_window_s * _NS
    recent = sorted(
        (aid, v[1]) for aid, v in s.recent_uwb.items() if v[3] == FRAME_EARTH and stamp_ns - v[0] <= window_ns
    )
    key = tuple(aid for aid, _ in recent)
    if key != s.mirror.key:
        s.reset_mirror(key)
    plane = anchor_plane(np.array([a for _, a in recent])) if len(recent) >= 3 else None
    if plane is None:
        return
    anchors = np.array([a for _, a in recent])
    tag = s.nominal[0:3] + f.lever
    tag_m = reflect(tag, *plane)
    if not is_range_ambiguous(tag, tag_m, anchors, p.uwb_range_std_m):
        return
    if p.uwb_tag_side_of_anchor_plane:
        if on_wrong_side(f, tag, plane):
            jump_to_mirror(f, tag_m, plane[1])
            f.count("uwb_side_prior_flip")
            s.reset_mirror(key)
        return
    states = np.stack([s.nominal, s.nominal])
    states[1, 0:3] = tag_m - f.lever
    hx = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column)
    res = prep.pr[None, :] - hx(states)
    chi2_pair = clock_free_chi2(res[:, accepted], prep.sigma_pr[accepted])
    dt_s = 0.0 if s.mirror_last_ns is None else (stamp_ns - s.mirror_last_ns) / _NS
    s.mirror_last_ns = stamp_ns
    if not s.mirror.add(chi2_pair, int(accepted.sum()), dt_s):
        return
    jump_to_mirror(f, tag_m, plane[1])
    f.count("uwb_mirror_switch")


def mirror_covariance(f: FilterFacade) -> tuple[float, np.ndarray] | None:
    """``uwb_mirror_covariance``: the covariance the mirror ambiguity adds to the published position,
    ``p d^2 n n^T`` (``d`` the distance from the tag to its mirror across the anchors' plane, ``n`` the
    plane's normal, ``p`` :func:`.mirror_test.mirror_wrong_side_probability`), as ``(p d^2, n n^T
    padded to the (6, 6) position-velocity block)``, or None when there is none: fewer than three
    anchors heard within ``uwb_init_window_s``, anchors that do not span a plane, a mirror that
    changes some range by a range 1-sigma (four or more anchors off their plane), or the side
    given by ``uwb_tag_side_of_anchor_plane``. The filter's own covariance is not changed: it
    describes the solution on the side the filter holds. With GNSS the probability of the wrong
    side uses ``uwb_mirror_gnss_std_m``, without GNSS it is 0.5. Beyond the paper."""
    s = f.state
    p = f.params
    if p.uwb_tag_side_of_anchor_plane:
        return None
    t = s.t_ns
    frame = s.frame
    if (t > s.mirror_valid_until_ns or s.anchor_version != s.mirror_plane_key[0]
            or frame != s.mirror_plane_key[1]):
        # the anchors heard within uwb_init_window_s: recomputed when an anchor appears, comes back,
        # moves or changes frame (anchor_version), or when the first of them may have fallen silent
        window_ns = p.uwb_init_window_s * _NS
        heard = [(aid, v) for aid, v in s.recent_uwb.items() if v[3] == frame and t - v[0] <= window_ns]
        s.mirror_plane_key = (s.anchor_version, frame)
        s.mirror_valid_until_ns = int(min((v[0] for _, v in heard), default=t) + window_ns)
        s.mirror_plane = None
        if len(heard) >= 3:
            anchors = np.array([v[1] for _, v in heard])
            plane = anchor_plane(anchors)
            if plane is not None:
                nn6 = np.zeros((6, 6))
                nn6[0:3, 0:3] = np.outer(plane[1], plane[1])
                off_plane = (anchors - plane[0]) @ plane[1]  # each anchor's distance from the plane
                # farthest from the plane first: the one whose range the mirror changes most, usually
                # the only one the test below has to look at
                listed = tuple(sorted(((*map(float, a), float(o)) for a, o in zip(anchors, off_plane, strict=True)),
                                      key=lambda row: -abs(row[3])))
                s.mirror_plane = (nn6, float(plane[0] @ plane[1]), tuple(float(v) for v in plane[1]), listed)
    cached = s.mirror_plane
    if cached is None:
        return None
    nn6, c_dot_n, (n0, n1, n2), anchors = cached
    # in Python floats (this runs at every output): sd the tag's signed distance from the plane, d = 2 |sd|
    x0, x1, x2 = s.nominal[0:3].tolist()
    l0, l1, l2 = f.lever_floats
    t0, t1, t2 = x0 + l0, x1 + l1, x2 + l2
    sd = t0 * n0 + t1 * n1 + t2 * n2 - c_dot_n
    d = 2.0 * abs(sd)
    if len(anchors) > 3:
        # four or more anchors: ambiguous only if the mirror (tag - 2 sd n) changes no range by a range
        # 1-sigma (MIRROR_MAX_RANGE_CHANGE_SIGMA, as mirror_test.is_range_ambiguous); its squared range
        # to anchor i is r_i^2 + 4 sd o_i, o_i the anchor's distance from the plane
        limit = MIRROR_MAX_RANGE_CHANGE_SIGMA * p.uwb_range_std_m
        for a0, a1, a2, o in anchors:
            r2 = (a0 - t0) ** 2 + (a1 - t1) ** 2 + (a2 - t2) ** 2
            if abs(math.sqrt(max(r2 + 4.0 * sd * o, 0.0)) - math.sqrt(r2)) >= limit:
                return None
    with_gnss = p.use_gnss and frame == FRAME_EARTH and s.clock_initialized
    prob = mirror_wrong_side_probability(d, p.uwb_mirror_gnss_std_m if with_gnss else None)
    return prob * d * d, nn6


def on_wrong_side(f: FilterFacade, tag: np.ndarray, plane: tuple[np.ndarray, np.ndarray]) -> bool:
    """True if ``tag`` lies on the other side of the anchors' ``plane`` (centroid, unit normal)
    than ``uwb_tag_side_of_anchor_plane`` says (a prior, not a test). "Up" is the local vertical:
    in the earth frame the radial direction, in the map frame (local ENU) +z."""
    s = f.state
    centroid, normal = plane
    if s.frame == FRAME_EARTH:
        up = tag / max(float(np.linalg.norm(tag)), 1.0)
    else:
        up = np.array([0.0, 0.0, 1.0])
    n_up = normal if float(normal @ up) >= 0.0 else -normal
    return float((tag - centroid) @ n_up) * int(f.params.uwb_tag_side_of_anchor_plane) < 0.0


def side_prior_uwb(f: FilterFacade, stamp_ns: int) -> None:
    """The installer's side of the anchors' plane without GNSS (UWB alone, or the map frame),
    checked after an accepted range at most once per ``uwb_init_window_s``: with GNSS the check
    runs at every GNSS epoch (:func:`mirror_check`); without it the side the UWB
    multilateration start happened to pick would otherwise stand. Beyond the paper."""
    s = f.state
    p = f.params
    if s.side_last_ns is not None and stamp_ns - s.side_last_ns < p.uwb_init_window_s * _NS:
        return
    s.side_last_ns = stamp_ns
    window_ns = p.uwb_init_window_s * _NS
    anchors = [v[1] for v in s.recent_uwb.values() if v[3] == s.frame and stamp_ns - v[0] <= window_ns]
    if len(anchors) < 3:
        return
    arr = np.array(anchors)
    plane = anchor_plane(arr)
    if plane is None:
        return
    tag = s.nominal[0:3] + f.lever
    tag_m = reflect(tag, *plane)
    if is_range_ambiguous(tag, tag_m, arr, p.uwb_range_std_m) and on_wrong_side(f, tag, plane):
        jump_to_mirror(f, tag_m, plane[1])
        f.count("uwb_side_prior_flip")


def jump_to_mirror(f: FilterFacade, tag_m: np.ndarray, normal: np.ndarray) -> None:
    """Move the state to the mirror image ``tag_m`` of the tag across the anchors' plane (unit
    ``normal``): position and velocity reflected, the error covariance by the same linear map
    (``P <- T P T^T``, exact)."""
    s = f.state
    m = householder(normal)
    t = np.eye(s.nominal.size)
    t[0:3, 0:3] = m
    t[3:6, 3:6] = m
    s.nominal[0:3] = tag_m - f.lever
    s.nominal[3:6] = m @ s.nominal[3:6]
    s.ckf = CubatureKalmanFilter(np.zeros(s.nominal.size), t @ s.ckf.p @ t.T)


def side_of_anchor_plane(f: FilterFacade, stamp_ns: int, min_distance_m: float = 0.1) -> int:
    """The side of the anchors' plane the state's tag is on: +1 above, -1 below (the local vertical,
    as ``uwb_tag_side_of_anchor_plane``), 0 when not initialised, fewer than three anchors were heard
    within ``uwb_init_window_s``, they span no plane, or the tag is within ``min_distance_m`` of it.
    While GNSS holds the state, this is the side GNSS chose; the caller may keep it for a period
    without GNSS (:meth:`reanchor_on_uwb`), when three anchors alone cannot tell the mirror apart."""
    s = f.state
    if not s.initialized:
        return 0
    win = f.params.uwb_init_window_s * _NS
    anchors = [a for (t, a, _, fr) in s.recent_uwb.values() if fr == s.frame and stamp_ns - t <= win]
    plane = anchor_plane(np.array(anchors)) if len(anchors) >= 3 else None
    if plane is None:
        return 0
    tag = s.nominal[0:3] + f.lever
    up = tag / max(float(np.linalg.norm(tag)), 1.0) if s.frame == FRAME_EARTH else np.array([0.0, 0.0, 1.0])
    n_up = plane[1] if float(plane[1] @ up) >= 0.0 else -plane[1]
    distance = float((tag - plane[0]) @ n_up)
    return 0 if abs(distance) < min_distance_m else (1 if distance > 0.0 else -1)
