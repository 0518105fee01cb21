"""Per-environment sonar kernels: the one implementation of the sonar model.

Every caller — the simulator's batched functions (:mod:`finkensim.sensors.sonar`), the compiled
closed loop (:mod:`finkensim.swarm`) and the gap replay (:mod:`finkensim.gap.model.replay`,
:mod:`finkensim.gap.model.predictive`) — computes sonar readings with these functions, fed by the same
:class:`~finkensim.sensors.sonar_model.SonarModel` record:

- geometry: :func:`shifted_plates_env` / :func:`displaced_plates_env` (plate surfaces at flight height),
  :func:`sonar_poses_env` (sonar origins and headings), :func:`sonar_hit` (nearest echo of one sonar over
  the rays of its beam, :func:`~finkensim.kernels.raycast.cast_ray_culled`), :func:`ideal_env`;
- cross-talk geometry: :func:`fire_slot` / :func:`fire_slots_env` (firing schedule),
  :func:`crosstalk_path` (shortest emitter → receiver path heard by a sonar);
- the error model of one reading: :func:`measured_reading` (echo error, constant and geometric
  cross-talk, clamp), built from :func:`echo_reading` and :func:`clamp_reading`;
- :func:`sonar_env`, :func:`down_env`: one environment's measured readings.

All are ``inline="always"`` numba functions of arrays, numbers and the model record, so compiled loops
can call them with work buffers allocated once. The functions called once per ray or reading take the model's
:class:`~finkensim.sensors.sonar_model.SonarScalars` (any record with the scalar fields works; the model itself
too, at the cost of reference-counting its arrays on every call). The model, the random-number layout and the units
are documented in :mod:`finkensim.sensors.sonar`. Horizontal sonars: S = ``sonar.mount_yaw.shape[0]``
(4 in the simulator).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels.cellgrid import build_env, grid_layout, query_env
from ..kernels.raycast import HIT_NONE, cast_ray_culled, plate_bands
from ..kernels.rng import STREAM_SONAR, STREAM_SONAR_SCHEDULE, counter_key, normal, uniform
from ..kernels.trig import sin_fast
from .correction_table import correct_readings_env
from .sonar_model import (CROSSTALK_CONSTANT, CROSSTALK_GEOMETRIC, DOWN_SONAR, ERROR_GAUSSIAN, ERROR_NONE,
                          ERROR_SEED, SCHEDULE_RANDOM_OFFSET, SCHEDULE_ROUND_ROBIN, sonar_scalars)

__all__ = ["shifted_plates_env", "displaced_plates_env", "sonar_poses_env", "sonar_pose", "sonar_hit", "store_ideal", "ideal_env", "fire_slot",
           "fire_slots_env", "sonar_spread", "crosstalk_path", "echo_error", "echo_reading", "clamp_reading", "measured_reading",
           "sonar_env", "down_env"]

#: Uniform index (inside sonar k's block 8k … 8k + 7 of a STREAM_SONAR cell) of the coin that decides
#: whether a receiver in geometric cross-talk position hears the emitter (drawn only when the model's
#: ``crosstalk_hear_probability`` is below 1).
HEAR_COIN = 6


# ---------------------------------------------------------------------------------------------
# geometry

@njit(cache=True, inline="always")
def shifted_plates_env(theta_b, plate_a, plate_b, normal_, lever, gain, pa_out, pb_out):
    """Plate surfaces at flight height, each shifted along its inward normal by min(lever·gain·sin θ, lever).

    theta_b (S,) rad plate angles; plate_a, plate_b, ``normal_`` (S, 2) m (the hanging plates and their
    inward normals); lever m (hinge height − altitude); gain: scale of the displacement (1 = the hinge
    model; the gap diagnosis fits other values). Writes pa_out, pb_out (S, 2) m. The sine is
    :func:`~finkensim.kernels.trig.sin_fast` (within 2·10⁻¹⁵ of libm's for |θ| ≤ π/2, where the hinge keeps the
    plates: the surface moves by < 2·10⁻¹⁵ · lever·gain, a femtometre; libm's beyond).
    """
    for s in range(theta_b.shape[0]):
        sh = lever * gain * sin_fast(theta_b[s])
        if sh > lever:
            sh = lever
        pa_out[s, 0] = plate_a[s, 0] + sh * normal_[s, 0]
        pa_out[s, 1] = plate_a[s, 1] + sh * normal_[s, 1]
        pb_out[s, 0] = plate_b[s, 0] + sh * normal_[s, 0]
        pb_out[s, 1] = plate_b[s, 1] + sh * normal_[s, 1]


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def displaced_plates_env(theta_b, plate_a, plate_b, normal_, lever, pa_out, pb_out):
    """Plate surfaces at flight height for one environment: theta_b (S,) rad → pa_out, pb_out (S, 2) m,
    each plate shifted along its inward normal by lever · sin θ (as ``Arena.plate_surfaces``)."""
    shifted_plates_env(theta_b, plate_a, plate_b, normal_, lever, 1.0, pa_out, pb_out)


@njit(cache=True, inline="always")
def sonar_poses_env(pos_b, yaw_b, sonar, sonar_buf):
    """Sonar origins and headings of one environment → sonar_buf (N, S, 4): (x m, y m, cos ψ, sin ψ), ψ = yaw + mount.

    The heading is the copter's (cos, sin) of its yaw rotated by the mount's (one sine and cosine per copter and per
    mount, not per sonar): within 10⁻¹⁵ + 2.3·10⁻¹⁶·|yaw + mount| of (cos ψ, sin ψ) of the float sum ψ (the sum's
    own rounding is the second term; ``tests/test_sonar.py`` checks the bound), i.e. < 10⁻¹⁵ m of a 3 m ray.
    """
    mount_yaw = sonar.mount_yaw
    offset = sonar.offset
    N = pos_b.shape[0]
    if N == 0:
        return
    # the mounts' (cos, sin) wait in copter 0's heading slots, which copter 0 overwrites last (each after reading it)
    for k in range(mount_yaw.shape[0]):
        sonar_buf[0, k, 2] = np.cos(mount_yaw[k])
        sonar_buf[0, k, 3] = np.sin(mount_yaw[k])
    for n in range(N - 1, -1, -1):
        cy = np.cos(yaw_b[n])
        sy = np.sin(yaw_b[n])
        for k in range(mount_yaw.shape[0]):
            cm = sonar_buf[0, k, 2]
            sm = sonar_buf[0, k, 3]
            c = cy * cm - sy * sm
            s = sy * cm + cy * sm
            sonar_buf[n, k, 0] = pos_b[n, 0] + offset * c
            sonar_buf[n, k, 1] = pos_b[n, 1] + offset * s
            sonar_buf[n, k, 2] = c
            sonar_buf[n, k, 3] = s


@njit(cache=True, inline="always")
def sonar_pose(sonar_buf, n, k):
    """Sonar k of copter n as placed by :func:`sonar_poses_env`: the tuple (x m, y m, cos ψ, sin ψ) of sonar_buf[n, k]."""
    return sonar_buf[n, k, 0], sonar_buf[n, k, 1], sonar_buf[n, k, 2], sonar_buf[n, k, 3]


@njit(cache=True, inline="always")
def sonar_hit(n, pose, psi, pos_b, walls, sonar, rays, bands, cand, n_cand):
    """Nearest echo of a sonar of copter n over the rays of its beam, not limited to the range.

    pose: the sonar's (x m, y m, cos ψ, sin ψ) (:func:`sonar_pose`); psi rad: its heading, yaw_b[n] + mount_yaw[k];
    rays (R,) rad: the beam's ray angles relative to it (``SonarModel.ray_angles``); sonar: the model's
    :class:`~finkensim.sensors.sonar_model.SonarScalars` (or the model; its ``radius`` is read). walls = (pa, pb,
    width, length) as in :func:`ideal_env`, bands from :func:`~finkensim.kernels.raycast.plate_bands`; the copters
    tested: all when ``n_cand`` < 0, else cand[:n_cand] (:func:`~finkensim.kernels.raycast.copter_hits`). Returns
    (t m, kind HIT_*, hx m, hy m): the distance (inf when a ray escapes nothing — never inside the arena), what was
    hit, and where (NaN if nothing).
    """
    ox, oy, cx, cy = pose
    R = rays.shape[0]
    best = np.inf
    bkind = HIT_NONE
    hx = np.nan
    hy = np.nan
    for r in range(R):
        if R == 1 and rays[0] == 0.0:
            dx = cx
            dy = cy
        else:
            a = psi + rays[r]
            dx = np.cos(a)
            dy = np.sin(a)
        t, hk = cast_ray_culled((ox, oy, dx, dy), n, pos_b, sonar.radius, walls, bands, cand, n_cand)
        if t < best:
            best = t
            bkind = hk
            hx = ox + t * dx
            hy = oy + t * dy
    return best, bkind, hx, hy


@njit(cache=True, inline="always")
def store_ideal(n, k, found, max_range, pose, dist, kind, hit):
    """The ideal reading of sonar k of copter n from its :func:`sonar_hit` ``found`` = (best, bkind, hx, hy) into
    dist[n, k], kind[n, k], hit[n, k] (as :func:`ideal_env`: beyond ``max_range`` m reads max_range, HIT_NONE); pose:
    the sonar's (:func:`sonar_pose`)."""
    # every array is read or written on every path (the branches choose numbers): see cast_ray_culled on why
    best, bkind, hx, hy = found
    ox, oy, dx, dy = pose
    d = best
    kd = bkind
    if best > max_range:
        d = max_range
        kd = HIT_NONE
        if not np.isfinite(best):
            hx = ox + max_range * dx
            hy = oy + max_range * dy
    dist[n, k] = d
    kind[n, k] = kd
    hit[n, k, 0] = hx
    hit[n, k, 1] = hy


@njit(cache=True, inline="always")
def ideal_env(pos_b, yaw_b, walls, sonar, ideal, grid, cells):
    """Ideal horizontal readings of one environment.

    pos_b (N, 2) m, yaw_b (N,) rad, walls = (pa, pb, width, length): pa/pb (S_p, 2) m displaced plate surfaces
    (:func:`displaced_plates_env`), width/length m. ideal = (sonar_buf, dist, kind, hit): writes sonar_buf (N, S, 4)
    (see :func:`sonar_poses_env`), dist (N, S) m (max_range when no echo), kind (N, S) int (HIT_*),
    hit (N, S, 2) m (nearest hit point, also beyond range).

    grid: an :class:`~finkensim.kernels.cellgrid.EngineGrid` (or a record with its ``on`` and geometry fields), cells:
    this environment's buffers of it. When ``grid.on``, the copters each ray is tested against are those the grid
    finds within max_range + radius + |offset| of the copter (rebuilt here): every copter a ray can hit within the
    range, so dist and kind are the brute force's bit for bit; a ray without an echo within range may then report
    a farther wall point in ``hit`` where the brute force reports a copter beyond the range.
    """
    sonar_buf, dist, kind, hit = ideal
    sonar_poses_env(pos_b, yaw_b, sonar, sonar_buf)
    bands = plate_bands(walls[0], walls[1], walls[2], walls[3])
    cell_start, order, spos, cell_of, found, found_d2 = cells
    layout = grid_layout(grid)
    if grid.on:
        build_env(pos_b, layout, cell_start, order, spos, cell_of)
    scalars = sonar_scalars(sonar)  # the per-ray calls take the scalars and the arrays apart (see SonarScalars)
    mount_yaw = sonar.mount_yaw
    rays = sonar.ray_angles
    # a hit at t ≤ max_range from the sonar has its circle's centre within t + radius of the sonar (exactly; the
    # computed t of a grazing ray can be off by ~sqrt(eps)·scale ≈ 1e-8·scale, hence the 1e-6 margin)
    reach = (scalars.max_range + scalars.radius + abs(scalars.offset)) * (1.0 + 1e-6)
    for n in range(pos_b.shape[0]):
        n_cand = -1
        if grid.on:
            n_cand = query_env(pos_b[n, 0], pos_b[n, 1], reach, n, layout, cell_start, order, spos, found, found_d2)
        for k in range(mount_yaw.shape[0]):
            pose = sonar_pose(sonar_buf, n, k)
            echo = sonar_hit(n, pose, yaw_b[n] + mount_yaw[k], pos_b, walls, scalars, rays, bands, found, n_cand)
            store_ideal(n, k, echo, scalars.max_range, pose, dist, kind, hit)


# ---------------------------------------------------------------------------------------------
# cross-talk geometry

@njit(cache=True, inline="always")
def fire_slot(seed, env_id, step, n, sonar, draw):
    """Firing slot (0 … n_slots − 1) of copter n at this step.

    ``draw`` picks the uniform of the random-offset schedule inside the copter's STREAM_SONAR_SCHEDULE
    cell: the simulator uses 0; the gap replay, which does not know the real schedule, uses its draw
    index so that its predictive ensemble spreads over the possible schedules.
    """
    if sonar.schedule == SCHEDULE_ROUND_ROBIN:
        return n % sonar.n_slots
    if sonar.schedule == SCHEDULE_RANDOM_OFFSET:
        u = uniform(counter_key(seed, env_id, step, n, STREAM_SONAR_SCHEDULE), draw)
        return min(int(u * sonar.n_slots), sonar.n_slots - 1)
    return 0


@njit(cache=True, inline="always")
def fire_slots_env(seed, env_id, step, sonar, slot, draw):
    """Firing slots of every copter of one environment → slot (N,) int64 (``draw`` as in :func:`fire_slot`)."""
    for n in range(slot.shape[0]):
        slot[n] = fire_slot(seed, env_id, step, n, sonar, draw)


@njit(cache=True, inline="always")
def sonar_spread(sonar):
    """An upper bound (m) on the distance between two sonars of one copter as :func:`sonar_poses_env` places them
    (origin + offset · unit heading): 2·|offset|; :func:`crosstalk_path`'s margin absorbs the rounding."""
    return 2.0 * abs(sonar.offset)


@njit(cache=True, inline="always")
def crosstalk_path(n, k, sonar_buf, slot, sonar, cand, n_cand, spread, scratch):
    """Shortest emitter→receiver path (m) heard by sonar (n, k) under geometric cross-talk; inf if none.

    Emitters are the sonars of other copters firing in copter n's slot (``slot`` (N,)), inside the
    receiver's cone and pointing at it, within 2·max_range. sonar_buf (N, S, 4) from :func:`sonar_poses_env`.
    The copters considered: all when ``n_cand`` < 0, else cand[:n_cand] (the result is a minimum: any order).
    spread m: an upper bound on the distance between any two sonars of one copter in sonar_buf
    (:func:`sonar_spread` for the buffers of :func:`sonar_poses_env`), or inf (nothing assumed): with it, a copter
    whose sonars all lie outside the receiver's cone is passed over with one test instead of one per sonar.
    scratch: int64 work buffer with room for every copter considered.
    """
    rx = sonar_buf[n, k, 0]
    ry = sonar_buf[n, k, 1]
    ux = sonar_buf[n, k, 2]
    uy = sonar_buf[n, k, 3]
    lim = 2.0 * sonar.max_range
    ch = sonar.cos_half_angle
    best = np.inf
    # Copter-level rejection: the cone (half angle α, cos α = ch) lies inside both half-planes e·w ≥ 0 bounded by its
    # edges (inward unit normals e1, e2). The sonars of copter m lie within ``spread`` of its sonar 0 (v from the
    # receiver), so e·v < −(spread + ε) for one edge puts every one of them more than ε outside the cone; there the
    # test below computes u·w − ch·L < −ε·sin α, far beyond its rounding (~1e-15·L) for ε = 1e-7·(1 + |r| + |v|) m
    # and sin α ≥ 0.01 (narrower cones skip this). NaN never passes over a copter; an infinite v only copters the
    # test below rejects too (L = inf is never < best).
    sa = np.sqrt(max(0.0, 1.0 - ch * ch))
    e1x = ux * sa - uy * ch
    e1y = ux * ch + uy * sa
    e2x = ux * sa + uy * ch
    e2y = uy * sa - ux * ch
    by_copter = spread < np.inf and sa >= 0.01
    pad = spread + 1e-7 * (1.0 + abs(rx) + abs(ry))
    # first the copters that can be heard (same slot, not n, not passed over), compacted without a branch (always
    # write, advance on a keep: whether a copter is kept is a coin flip the processor cannot predict), then their
    # emitters
    M = sonar_buf.shape[0] if n_cand < 0 else n_cand
    kept = 0
    for c in range(M):
        m = c if n_cand < 0 else cand[c]
        vx = sonar_buf[m, 0, 0] - rx
        vy = sonar_buf[m, 0, 1] - ry
        lim_v = -(pad + 1e-7 * (abs(vx) + abs(vy)))
        outside = by_copter & ((e1x * vx + e1y * vy < lim_v) | (e2x * vx + e2y * vy < lim_v))
        scratch[kept] = m
        kept += (m != n) & (slot[m] == slot[n]) & (not outside)
    for c in range(kept):
        m = scratch[c]
        for j in range(sonar_buf.shape[1]):
            wx = sonar_buf[m, j, 0] - rx
            wy = sonar_buf[m, j, 1] - ry
            L = np.sqrt(wx * wx + wy * wy)
            cl = ch * L
            # the plain test (L in (0, lim], shorter than the best, inside both cones) without a branch: whether an
            # emitter passes is unpredictable, and a select costs less than the mispredictions it saves
            rejected = (L <= 0.0) | (L > lim) | (L >= best)
            ok = (not rejected) & (ux * wx + uy * wy >= cl) & (-(sonar_buf[m, j, 2] * wx + sonar_buf[m, j, 3] * wy) >= cl)
            best = L if ok else best
    return best


# ---------------------------------------------------------------------------------------------
# the error model of one reading

@njit(cache=True, inline="always")
def echo_error(key, k, sonar):
    """The random error (m) of an echo reading of sonar k under ``sonar.error`` (random numbers of block k of
    ``key``); :func:`echo_reading` adds it, times range_scale, to range_scale · d + bias. Not for ``ERROR_NONE`` (no
    error drawn)."""
    if sonar.error == ERROR_GAUSSIAN:
        return sonar.sigma * normal(key, 4 * k + 1)
    u = uniform(key, 8 * k + 1)
    R = np.sqrt(-2.0 * sonar.sigma * sonar.sigma * np.log(u))
    if sonar.error == ERROR_SEED:
        return R - sonar.rayleigh_s
    return sonar.rayleigh_sign * (R - sonar.rayleigh_s)


@njit(cache=True, inline="always")
def echo_reading(d, echo, key, k, sonar, err=None):
    """Echo reading (m, unclamped) of sonar k for true distance d; ``echo`` False → max_range exactly.

    An echo reads range_scale · (d + e) + bias with e the error of ``sonar.error`` (:func:`echo_error`: random
    numbers of block k of ``key``, see :mod:`finkensim.sensors.sonar`), or ``err`` m when given (that error drawn
    beforehand, e.g. once for many evaluations of other parameters). The sonar times an echo and converts the time
    with its assumed speed of sound, so a wrong speed (range_scale ≠ 1) scales the echo's path, its error
    included; the bias is a constant offset of the conversion. (Written range_scale · d + bias + range_scale · e:
    at range_scale 1 the same floating-point operations as before the error was scaled.)
    """
    if not echo:
        return sonar.max_range
    y = d * sonar.range_scale + sonar.bias
    if sonar.error == ERROR_NONE:
        return y
    if err is None:
        return y + echo_error(key, k, sonar) * sonar.range_scale
    return y + err * sonar.range_scale


@njit(cache=True, inline="always")
def clamp_reading(y, sonar):
    """y clamped to [min_range, max_range] (m)."""
    return min(sonar.max_range, max(sonar.min_range, y))


@njit(cache=True, inline="always")
def measured_reading(d, echo, path, key, k, sonar, err=None):
    """The measured reading (m, clamped) of one sonar: echo error, then cross-talk, then the clamp.

    d m true distance (max_range without an echo); echo: an echo within range; path m: the shortest
    cross-talk path heard (:func:`crosstalk_path`; inf if none or not geometric); key, k: the random
    numbers (block k of the STREAM_SONAR cell ``key``); err: the echo's error if drawn beforehand
    (:func:`echo_reading`). Constant cross-talk replaces the reading by d/2
    with probability ``crosstalk_probability``; geometric cross-talk reads path/2 + jitter when that
    arrives first (heard with probability ``crosstalk_hear_probability``). A cross-talk reading is an
    echo time converted like any other, so ``range_scale`` and ``bias`` apply to it too: range_scale · d/2
    + bias, its jitter scaled too (they are 1 and 0 unless the gap diagnosis fits them, and then the reading is d/2
    exactly).
    """
    y = echo_reading(d, echo, key, k, sonar, err)
    if sonar.crosstalk & CROSSTALK_CONSTANT:
        if uniform(key, 8 * k) < sonar.crosstalk_probability:
            y = 0.5 * d * sonar.range_scale + sonar.bias
    if sonar.crosstalk & CROSSTALK_GEOMETRIC and path < np.inf:
        if sonar.crosstalk_hear_probability >= 1.0 or uniform(key, 8 * k + HEAR_COIN) < sonar.crosstalk_hear_probability:
            c = 0.5 * path * sonar.range_scale + sonar.bias
            if sonar.crosstalk_jitter > 0.0:
                c += sonar.crosstalk_jitter * normal(key, 4 * k + 2) * sonar.range_scale
            if c < y:
                y = c
    return clamp_reading(y, sonar)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def sonar_env(pos_b, yaw_b, walls, sonar, counter, work, out, grid, cells):
    """Measured horizontal readings of one environment → out (N, S) m, in [min_range, max_range].

    Same geometry arguments and grid as :func:`ideal_env`; work = (sonar_buf, dist, kind, hit, slot): its work
    buffers (the ideal values are left in dist/kind/hit) and slot (N,) int64; counter = (seed, env_id, step) keys
    the random numbers. With the grid on, the cross-talk emitters are searched among the copters within
    2·(max_range + |offset|) of the receiver's copter (all that can be within 2·max_range of its sonar).
    """
    sonar_buf, dist, kind, hit, slot = work
    seed, env_id, step = counter
    ideal_env(pos_b, yaw_b, walls, sonar, (sonar_buf, dist, kind, hit), grid, cells)
    scalars = sonar_scalars(sonar)  # the per-reading calls take the scalars only (see SonarScalars)
    n_sonars = sonar.mount_yaw.shape[0]
    geometric = scalars.crosstalk & CROSSTALK_GEOMETRIC
    if geometric:
        fire_slots_env(seed, env_id, step, scalars, slot, 0)
    cell_start, order, spos, cell_of, found, found_d2 = cells
    reach = 2.0 * (scalars.max_range + abs(scalars.offset)) * (1.0 + 1e-6)
    spread = sonar_spread(scalars)
    N = pos_b.shape[0]
    # crosstalk_path's scratch (row 0) and, without the grid, the candidate list (row 1; with it, the query's)
    xt_buf = np.empty((2, N if geometric else 0), dtype=np.int64)
    cand = found if grid.on else xt_buf[1]
    for n in range(N):
        key = counter_key(seed, env_id, step, n, STREAM_SONAR)
        n_cand = 0
        if geometric:
            n_found = N
            if grid.on:  # the grid ideal_env built
                n_found = query_env(pos_b[n, 0], pos_b[n, 1], reach, n, grid_layout(grid), cell_start, order, spos,
                                    found, found_d2)
            # the other copters firing in n's slot (the others crosstalk_path skips), once for n's S sonars, compacted
            # without a branch (always write, advance on a match: with several slots a match is a coin flip the
            # processor cannot predict)
            for c in range(n_found):
                m = found[c] if grid.on else c
                cand[n_cand] = m
                n_cand += (slot[m] == slot[n]) & (m != n)
        for k in range(n_sonars):
            path = crosstalk_path(n, k, sonar_buf, slot, scalars, cand, n_cand, spread, xt_buf[0]) if geometric else np.inf
            out[n, k] = measured_reading(dist[n, k], kind[n, k] != HIT_NONE, path, key, k, scalars)
    if sonar.correction.shape[0] > 0:  # the learned correction (sonar.correction_file)
        correct_readings_env(out, dist, kind, sonar.correction, scalars, counter)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def down_env(alt_b, sonar, seed, env_id, step, out):
    """Down-sonar readings of one environment: true altitude alt_b (N,) m → out (N,) m (clamped)."""
    scalars = sonar_scalars(sonar)
    for n in range(alt_b.shape[0]):
        key = counter_key(seed, env_id, step, n, STREAM_SONAR)
        d = alt_b[n]
        out[n] = clamp_reading(echo_reading(d, d <= scalars.max_range, key, DOWN_SONAR, scalars), scalars)
