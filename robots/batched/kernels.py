"""Compiled kernels of the batched simulator (numba, no Python in the loop).

Every function works on the arrays of :class:`dfrl.robots.batched.world.BatchedWorld`: one row
per robot, the robot's own random generators (``numpy.random.Generator`` objects, which numba
draws from exactly as numpy does), and the constants of the simulation in two vectors indexed by
the ``P_*`` and ``I_*`` names below. The maths follow :class:`dfrl.robots.env.EPuckEnv` line by
line (robots/README.md, "The batched simulator", says where they differ and by how much).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# float parameters, P[...]
P_BODY_RADIUS = 0
P_SENSOR_RANGE = 1
P_RAY_START = 2  # where a ray starts, from the centre (inside the body, beyond the wheels)
P_NOISE_STD = 3
P_STEP_LENGTH = 4  # top speed x control period: progress 1
P_RESPAWN_CLEARANCE = 5
P_STUCK_DISTANCE = 6
P_CONTACT = 7  # clearance at or below which the body touches (pybullet's margin)
P_ALIVE = 8
P_FORWARD = 9
P_NEAR_THRESHOLD = 10
P_NEAR_PENALTY = 11
P_COLLISION_PENALTY = 12
N_FLOAT_PARAMS = 13
# integer parameters, I[...]
I_STUCK_STEPS = 0
I_RESPAWN = 1  # 1: a collision ends the episode
I_LEVELS = 2
N_INT_PARAMS = 3
#: most draws a free pose may take before the arena counts as too crowded (as ArenaSpec's)
MAX_TRIES = 10_000
TWO_PI = 2.0 * math.pi


@njit(cache=True)
def box_distance(px, py, box):
    """Signed distance from a point to a box's footprint (negative inside)."""
    dx, dy = px - box[0], py - box[1]
    lx = box[4] * dx + box[5] * dy
    ly = -box[5] * dx + box[4] * dy
    qx, qy = abs(lx) - box[2], abs(ly) - box[3]
    ox, oy = max(qx, 0.0), max(qy, 0.0)
    return math.sqrt(ox * ox + oy * oy) + min(max(qx, qy), 0.0)


@njit(cache=True)
def clearance(px, py, boxes, lo, hi):
    """Signed distance from a point to the nearest box of rows ``lo .. hi``."""
    best = np.inf
    for b in range(lo, hi):
        d = box_distance(px, py, boxes[b])
        if d < best:
            best = d
    return best


@njit(cache=True)
def ray_hit(px, py, ux, uy, box, t0, t1):
    """Where a ray from ``(px, py)`` along the unit ``(ux, uy)`` enters a box, between ``t0``
    and ``t1`` (inf: it does not). A box that holds the point at ``t0`` is not seen, as a
    pybullet ray ignores a convex shape it starts in."""
    ox, oy = px - box[0], py - box[1]
    c, s = box[4], box[5]
    lo_ = (c * ox + s * oy, -s * ox + c * oy)
    ld = (c * ux + s * uy, -s * ux + c * uy)
    half = (box[2], box[3])
    tmin, tmax = -np.inf, np.inf
    for k in range(2):
        if abs(ld[k]) < 1e-12:
            if abs(lo_[k]) > half[k]:
                return np.inf
        else:
            ta = (-half[k] - lo_[k]) / ld[k]
            tb = (half[k] - lo_[k]) / ld[k]
            if ta > tb:
                ta, tb = tb, ta
            tmin = max(tmin, ta)
            tmax = min(tmax, tb)
    if tmax < tmin or tmin < t0 or tmin > t1:
        return np.inf
    return tmin


@njit(cache=True)
def sense(i, pose, dist, boxes, lo, hi, angles, P, rng):
    """Fill ``dist[i]`` with what robot ``i``'s sensors see: the distance from the body's rim
    to the first box along each ray, ``sensor_range`` when none; noisy when ``P_NOISE_STD``."""
    x, y, yaw = pose[i, 0], pose[i, 1], pose[i, 2]
    rim, rng_ = P[P_BODY_RADIUS], P[P_SENSOR_RANGE]
    t0, t1 = P[P_RAY_START], rim + rng_
    for k in range(angles.shape[0]):
        a = yaw + angles[k]
        ux, uy = math.cos(a), math.sin(a)
        t = np.inf
        for b in range(lo, hi):
            if boxes[b, 6] > 0.0:
                tb = ray_hit(x, y, ux, uy, boxes[b], t0, t1)
                if tb < t:
                    t = tb
        d = rng_ if t == np.inf else min(max(t - rim, 0.0), rng_)
        dist[i, k] = d
    std = P[P_NOISE_STD]
    if std > 0.0:
        for k in range(angles.shape[0]):  # numpy draws all, then keeps the seen ones
            noise = rng.normal(0.0, std)
            if dist[i, k] < rng_:
                dist[i, k] = min(max(dist[i, k] + noise, 0.0), rng_)


@njit(cache=True)
def proximity(d, sensor_range):
    """The observation of a distance, as ``EPuckEnv`` makes it (float32)."""
    return np.float32(1.0 - d / sensor_range)


@njit(cache=True)
def discretise(dist_row, sensor_range, groups, levels):
    """The tabular state of one robot's readings (``dfrl.robots.state.Discretiser``)."""
    top = levels - 1
    state, radix = 0, 1
    for g in range(groups.shape[0]):
        value = 0.0
        for j in range(groups.shape[1]):
            k = groups[g, j]
            if k >= 0:
                v = np.float64(proximity(dist_row[k], sensor_range))
                if v > value:
                    value = v
        level = int(math.ceil(value * top)) if value > 0.0 else 0
        state += min(level, top) * radix
        radix *= levels
    return state


@njit(cache=True)
def trail_restart(i, trail, trail_len, trail_head, x, y):
    """Forget robot ``i``'s trail and start it at ``(x, y)``."""
    trail_head[i] = 0
    trail_len[i] = 1
    trail[i, 0, 0] = x
    trail[i, 0, 1] = y


@njit(cache=True)
def trail_stuck(i, trail, trail_len, trail_head, x, y, window, min_distance):
    """Append ``(x, y)`` to robot ``i``'s trail (the last ``window + 1`` positions); True when
    it moved less than ``min_distance`` over the window (``EPuckEnv._stuck``)."""
    cap = trail.shape[1]
    if trail_len[i] < cap:
        slot = (trail_head[i] + trail_len[i]) % cap
        trail_len[i] += 1
    else:
        slot = trail_head[i]
        trail_head[i] = (trail_head[i] + 1) % cap
    trail[i, slot, 0] = x
    trail[i, slot, 1] = y
    if window == 0 or trail_len[i] <= window:
        return False
    h = trail_head[i]
    return math.hypot(x - trail[i, h, 0], y - trail[i, h, 1]) < min_distance


@njit(cache=True)
def free_pose(rng, boxes, lo, hi, hw, hd, clear):
    """A uniformly random pose whose disc of radius ``clear`` is free, drawn as
    ``ArenaSpec.sample_free_pose`` draws it; ``ok`` False when ``MAX_TRIES`` draws failed."""
    for _ in range(MAX_TRIES):
        x = rng.uniform(-hw + clear, hw - clear)
        y = rng.uniform(-hd + clear, hd - clear)
        yaw = rng.uniform(-math.pi, math.pi)
        if clearance(x, y, boxes, lo, hi) >= clear:
            return x, y, yaw, True
    return 0.0, 0.0, 0.0, False


@njit(cache=True)
def place(
    i, x, y, yaw, pose, prev, dist, trail, trail_len, trail_head, boxes, lo, hi, angles, P, rng
):
    """Put robot ``i`` at rest at a pose and read its sensors."""
    pose[i, 0], pose[i, 1], pose[i, 2] = x, y, yaw
    prev[i] = 0
    trail_restart(i, trail, trail_len, trail_head, x, y)
    sense(i, pose, dist, boxes, lo, hi, angles, P, rng)


@njit(cache=True)
def respawn(
    i,
    pose,
    prev,
    dist,
    trail,
    trail_len,
    trail_head,
    arena,
    first,
    count,
    half,
    boxes,
    angles,
    P,
    rng,
):
    """A reset without a seed: a random free pose. False when the arena is too crowded."""
    a = arena[i]
    lo, hi = first[a], first[a] + count[a]
    x, y, yaw, ok = free_pose(rng, boxes, lo, hi, half[a, 0], half[a, 1], P[P_RESPAWN_CLEARANCE])
    if ok:
        place(
            i,
            x,
            y,
            yaw,
            pose,
            prev,
            dist,
            trail,
            trail_len,
            trail_head,
            boxes,
            lo,
            hi,
            angles,
            P,
            rng,
        )
    return ok


@njit(cache=True)
def wrap(angle):
    """An angle in ``[-pi, pi]``."""
    return angle - TWO_PI * np.round(angle / TWO_PI)


@njit(cache=True)
def move(
    i,
    action,
    pose,
    prev,
    dist,
    trail,
    trail_len,
    trail_head,
    arena,
    first,
    count,
    boxes,
    angles,
    motion,
    P,
    I,
    rng,
    motion_rng,
    out,
):
    """One control step of robot ``i``: drive, stop at contact, sense, reward.

    ``rng`` draws the sensor noise (as the environment's generator does in pybullet),
    ``motion_rng`` the motion's spread. ``out`` receives ``(reward, collision, stuck,
    progress)`` (1.0/0.0 for the flags).
    """
    a = arena[i]
    lo, hi = first[a], first[a] + count[a]
    x0, y0, yaw0 = pose[i, 0], pose[i, 1], pose[i, 2]
    m = motion[prev[i], action]  # mean (forward, left, turn), then their spread
    fwd = m[0] + m[3] * motion_rng.normal()
    left = m[1] + m[4] * motion_rng.normal()
    dyaw = m[2] + m[5] * motion_rng.normal()
    c, s = math.cos(yaw0), math.sin(yaw0)
    dx, dy = c * fwd - s * left, s * fwd + c * left
    rim, contact = P[P_BODY_RADIUS], P[P_CONTACT]
    gap1 = clearance(x0 + dx, y0 + dy, boxes, lo, hi) - rim
    collision = gap1 <= contact
    if collision:  # the body stops where it meets the obstacle (the part of the step before)
        gap0 = clearance(x0, y0, boxes, lo, hi) - rim
        f = 0.0
        if gap0 > gap1:
            f = min(max(gap0 / (gap0 - gap1), 0.0), 1.0)
        dx, dy, dyaw = f * dx, f * dy, f * dyaw
        prev[i] = 0
    else:
        prev[i] = action + 1
    x1, y1, yaw1 = x0 + dx, y0 + dy, wrap(yaw0 + dyaw)
    pose[i, 0], pose[i, 1], pose[i, 2] = x1, y1, yaw1
    heading = yaw0 + 0.5 * wrap(yaw1 - yaw0)
    progress = (dx * math.cos(heading) + dy * math.sin(heading)) / P[P_STEP_LENGTH]
    sense(i, pose, dist, boxes, lo, hi, angles, P, rng)
    stuck = trail_stuck(
        i, trail, trail_len, trail_head, x1, y1, I[I_STUCK_STEPS], P[P_STUCK_DISTANCE]
    )
    p_max = 0.0
    for k in range(angles.shape[0]):
        v = np.float64(proximity(dist[i, k], P[P_SENSOR_RANGE]))
        if v > p_max:
            p_max = v
    r = P[P_ALIVE] + P[P_FORWARD] * min(max(progress, -1.0), 1.0)
    thr = P[P_NEAR_THRESHOLD]
    if p_max > thr:
        r -= P[P_NEAR_PENALTY] * (p_max - thr) / (1.0 - thr)
    if collision:
        r -= P[P_COLLISION_PENALTY]
    out[0] = r
    out[1] = 1.0 if collision else 0.0
    out[2] = 1.0 if stuck else 0.0
    out[3] = progress


@njit(cache=True)
def step_all(
    actions,
    pose,
    prev,
    dist,
    trail,
    trail_len,
    trail_head,
    arena,
    first,
    count,
    boxes,
    angles,
    motion,
    P,
    I,
    rngs,
    motion_rngs,
    out,
):
    """One control step of every robot; ``out[i]`` as :func:`move`'s."""
    for i in range(pose.shape[0]):
        move(
            i,
            actions[i],
            pose,
            prev,
            dist,
            trail,
            trail_len,
            trail_head,
            arena,
            first,
            count,
            boxes,
            angles,
            motion,
            P,
            I,
            rngs[i],
            motion_rngs[i],
            out[i],
        )


@njit(cache=True)
def wander(
    steps,
    n_actions,
    pose,
    prev,
    dist,
    trail,
    trail_len,
    trail_head,
    arena,
    first,
    count,
    half,
    boxes,
    angles,
    motion,
    P,
    I,
    rngs,
    motion_rngs,
    policy_rngs,
):
    """``steps`` control steps of every robot with uniform random actions drawn from
    ``policy_rngs[i]``, respawning a robot whose episode ends (no learning). Returns the first
    robot whose arena had no free pose left, or -1."""
    out = np.zeros(4)
    for i in range(pose.shape[0]):
        for _ in range(steps):
            a = policy_rngs[i].integers(0, n_actions)
            move(
                i,
                a,
                pose,
                prev,
                dist,
                trail,
                trail_len,
                trail_head,
                arena,
                first,
                count,
                boxes,
                angles,
                motion,
                P,
                I,
                rngs[i],
                motion_rngs[i],
                out,
            )
            if (out[1] > 0.0 and I[I_RESPAWN] == 1) or out[2] > 0.0:
                if not respawn(
                    i,
                    pose,
                    prev,
                    dist,
                    trail,
                    trail_len,
                    trail_head,
                    arena,
                    first,
                    count,
                    half,
                    boxes,
                    angles,
                    P,
                    rngs[i],
                ):
                    return i
    return -1
