"""The device side of :mod:`.cuda_kernel`: its device functions and kernels, for numba's CUDA target.

Imported only when a GPU (or numba's CUDA simulator) is asked for: importing
it compiles the helpers' sources for the device (:func:`.kernel.compile_helpers`);
each kernel compiles at its first launch, inside
:func:`.cuda_kernel.strict_arithmetic`. The kernels refer to ``cuda`` as a
module global, as numba's simulator needs to run them.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from .. import telegraph
from . import kernel
from .cuda_table import (
    BLACK,
    CDS,
    CDS_INTERVAL,
    EXPOSURE,
    FRAME_BLACK_SIGMA,
    FRAME_PERIOD,
    FULL_WELL,
    K_ADC,
    NL_A,
    NL_B,
    NL_C,
    NL_SCALE,
    NL_SIZE,
    NORMAL_ABOVE,
    READ_KIND,
    READ_SCALE,
    ROW_SIGMA,
    STEP,
    TOP,
    scalar_numpy,
)
from .plan import (  # the switches' and the key rows' indices, derived from the stages' table by name
    KEY_BLACK,
    KEY_COL,
    KEY_ROW,
    KEY_SF,
    KEY_SHOT,
    S_ADC,
    S_BLINK_EXACT,
    S_BLINKERS,
    S_COL,
    S_ELECTRONS,
    S_EXACT,
    S_NL,
    S_NOISY,
    S_OFFSET,
    S_READ,
    S_ROW,
    S_SF,
    S_TRAPS,
)

npx = scalar_numpy(cuda)  #: what ``np`` stands for in the helpers on the device
dev = cuda.jit(device=True, fastmath=False)
h = kernel.compile_helpers(dev, numpy=npx, skip=("occupancy",))  # it allocates: the device's form is below
uniform_pair, normal_from, normal_pair_from = h["uniform_pair"], h["normal_from"], h["normal_pair_from"]
poisson_one, tukey_lambda_cell, tukey_lambda_at = h["poisson_one"], h["tukey_lambda_cell"], h["tukey_lambda_at"]
frame_states, inside = h["frame_states"], h["inside"]
floor, rint = npx.floor, npx.rint


@dev
def normal(index, frame, seq, k0, k1):
    """A row's, a column's or a frame's normal (kernel._normal)."""
    u1, u2 = uniform_pair(np.uint64(index), frame, seq, np.uint64(0), k0, k1)
    return normal_from(u1, u2)


MAX_EVENTS = int(telegraph.MAX_EVENTS)
_POWERS = MAX_EVENTS + 1  # a local array's length must be a constant, not an expression
_OCCUPANCY_WORD = np.uint64(telegraph.OCCUPANCY << 4)
occupancy_uniform, occupancy_events, occupancy_walk = (h[k] for k in ("occupancy_uniform", "occupancy_events",
                                                                      "occupancy_walk"))


@dev
def occupancy(frame, x, y, up, down, t, index, slot, seq, k0, k1):
    """telegraph.occupancy on the device: its two parts compiled from telegraph's source, its arrays local to the
    thread (MAX_EVENTS long) and the event times sorted by insertion (numpy's sort gives the same sorted values)."""
    word0 = slot | _OCCUPANCY_WORD
    node = np.uint64(frame)
    n = occupancy_events(x, y, up, down, t, occupancy_uniform(index, node, seq, word0, 0, k0, k1))
    if n == 0:
        return t if x > 0.5 else 0.0
    mu = 1.0 - (up + down) / max(up, down)
    powers = cuda.local.array(_POWERS, np.float64)
    times = cuda.local.array(MAX_EVENTS, np.float64)
    powers[0] = 1.0
    for i in range(n):
        powers[i + 1] = powers[i] * mu
    for i in range(n):
        v = occupancy_uniform(index, node, seq, word0, 1 + i, k0, k1) * t
        q = i
        while q > 0 and times[q - 1] > v:
            times[q] = times[q - 1]
            q -= 1
        times[q] = v
    return occupancy_walk(x, y, up, down, t, n, powers, times, index, node, seq, word0, k0, k1)


@dev
def find(ptr, col, r, c):
    """Where column ``c`` of row ``r`` sits in a row-sorted sparse list (``ptr`` by row, ``col`` sorted within a
    row), or -1."""
    lo = ptr[r]
    hi = ptr[r + 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if col[mid] < c:
            lo = mid + 1
        else:
            hi = mid
    return lo if (lo < ptr[r + 1] and col[lo] == c) else -1


@cuda.jit(fastmath=False)
def lines(s, it):
    """Each item's row terms (B, h), column terms (B, w) and black level per 2 x 2 cell (B, 4), from its plan
    ``which[b]``: ``s`` the plans' arrays (:data:`.cuda_table.Shared`), ``it`` the launch's (:data:`.cuda_table.Items`;
    ``rowval``, ``colterm`` and ``cell_black`` are written), each read by name."""
    frames, which, corners, h, w, flags = it.frames, it.which, it.corners, it.h, it.w, it.flags
    rowval, colterm, cell_black = it.rowval, it.colterm, it.cell_black
    seqs, keys, numbers, row_offset, col_sigma, col_offset, cell_offsets = (s.seqs, s.keys, s.numbers, s.row_offset,
                                                                            s.col_sigma, s.col_offset, s.cell_offsets)
    t, b = cuda.grid(2)
    if b >= frames.size or t >= h + w + 4:
        return
    p = which[b]
    po = it.offsets_of[b]  # the offsets' row: the plan's, or the item's own (offsets that change each frame)
    fr = np.uint64(frames[b])
    sq = seqs[p]
    if t < h:
        if flags[p, S_ROW]:
            r = corners[b, 0] + t
            rowval[b, t] = numbers[p, ROW_SIGMA] * normal(r, fr, sq, keys[p, KEY_ROW, 0], keys[p, KEY_ROW, 1]) + row_offset[po, r]
    elif t < h + w:
        if flags[p, S_COL]:
            c = corners[b, 1] + (t - h)
            colterm[b, t - h] = col_offset[po, c] + col_sigma[p, c] * normal(c, fr, sq, keys[p, KEY_COL, 0], keys[p, KEY_COL, 1])
    else:
        q = t - h - w
        sigma = numbers[p, FRAME_BLACK_SIGMA]
        err = sigma * normal(0, fr, sq, keys[p, KEY_BLACK, 0], keys[p, KEY_BLACK, 1]) if sigma > 0.0 else 0.0
        cell_black[b, q] = (numbers[p, BLACK] + cell_offsets[p, q]) + err


@dev
def _inside_item(index, corners, b, h, w, cols):
    """Whether pixel ``index`` lies inside item ``b`` (``h`` x ``w`` at ``corners[b]``)."""
    r = np.int64(index // np.uint64(cols)) - corners[b, 0]
    c = np.int64(index % np.uint64(cols)) - corners[b, 1]
    return 0 <= r < h and 0 <= c < w


@dev
def _states_at(frame, seq, t, up, down, dt, index, slot, k0, k1):
    """Chain ``t``'s (frame, sequence word, state at the frame's start, state at its end): what both telegraph
    kernels start from."""
    sq = np.uint64(seq)
    x, y = frame_states(frame, up[t], down[t], dt, index[t], slot[t], sq, k0, k1)
    return frame, sq, x, y


@cuda.jit(fastmath=False)
def trap_values(frames, which, corners, h, w, cols, seqs, start, up, down, size, index, slot, numbers, ints, tkeys,
                out):
    """What each trap adds in each item's frame (e-), (B, most traps of a plan): kernel._trap_values. Item ``b``'s
    plan ``p`` holds the traps ``start[p]`` to ``start[p + 1]`` of the arrays; only those inside the item are made
    (the others are never read)."""
    t, b = cuda.grid(2)
    if b >= frames.size:
        return
    p = which[b]
    q = start[p] + t
    if q >= start[p + 1] or not _inside_item(index[q], corners, b, h, w, cols):
        return
    dt = numbers[p, FRAME_PERIOD]
    k0, k1 = tkeys[p, 0], tkeys[p, 1]
    frame, sq, x, y = _states_at(frames[b], seqs[p], q, up, down, dt, index, slot, k0, k1)
    if ints[p, CDS]:
        sig = inside(frame, x, y, up[q], down[q], dt, numbers[p, CDS_INTERVAL], index[q], slot[q], sq, k0, k1)
        out[b, t] = size[q] * (sig - x)
    else:
        out[b, t] = size[q] * x


@cuda.jit(fastmath=False)
def blink_values(frames, which, corners, h, w, cols, seqs, start, up, down, size, index, slot, numbers, bkeys, out):
    """Each blinking pixel's extra dark charge in each item's frame (e-), (B, most blinking pixels of a plan):
    kernel._blink_values; plan ``p``'s pixels are ``start[p]`` to ``start[p + 1]``; only those inside the item
    (``h`` x ``w`` at its corner; the others are never read)."""
    t, b = cuda.grid(2)
    if b >= frames.size:
        return
    p = which[b]
    q = start[p] + t
    if q >= start[p + 1] or not _inside_item(index[q], corners, b, h, w, cols):
        return
    dt, exposure = numbers[p, FRAME_PERIOD], numbers[p, EXPOSURE]
    k0, k1 = bkeys[p, 0], bkeys[p, 1]
    frame, sq, x, y = _states_at(frames[b], seqs[p], q, up, down, dt, index, slot, k0, k1)
    end = inside(frame, x, y, up[q], down[q], dt, exposure, index[q], slot[q], sq, k0, k1)
    out[b, t] = size[q] * occupancy(frame, x, end, up[q], down[q], exposure, index[q], slot[q], sq, k0, k1)


@cuda.jit(fastmath=False)
def pixel_sums(which, groups, start, first, index, corners, h, w, cols, values, out):
    """Per trapped pixel inside each item, its traps' values summed in slot order (telegraph.per_pixel), (B, most
    trapped pixels of a plan). Plan ``p``'s pixels are ``groups[p]`` to ``groups[p + 1]``, pixel ``g``'s traps
    ``first[g]`` to ``first[g + 1]`` of the arrays (``values`` holds them from ``start[p]``)."""
    g, b = cuda.grid(2)
    if b >= values.shape[0]:
        return
    p = which[b]
    q = groups[p] + g
    if q >= groups[p + 1] or not _inside_item(index[first[q]], corners, b, h, w, cols):
        return
    base = start[p]
    s = values[b, first[q] - base]
    for e in range(first[q] + 1, first[q + 1]):
        s = s + values[b, e - base]
    out[b, g] = s


@cuda.jit(fastmath=False)
def pixels(s, it, out_dn, out_e):
    """Every stage of one pixel of one item (kernel._render_rows, in its order): grid (columns, rows, items). Item
    ``b`` reads plan ``which[b]``'s maps, switches and numbers: ``s`` the plans' arrays (:data:`.cuda_table.Shared`),
    ``it`` the launch's (:data:`.cuda_table.Items`), each read by name."""
    noisy, exact, sf, ints, numbers, gain, keys, seqs = s.noisy, s.exact, s.sf, s.ints, s.numbers, s.col_gain, s.keys, s.seqs
    nl_table, offset, read_table, rts_ptr, rts_col, groups = s.nl, s.offset, s.read_table, s.rts_ptr, s.rts_col, s.trap_groups
    blink_ptr, blink_col, blinks = s.blink_ptr, s.blink_col, s.blink_start
    frames, which, corners, h, w, cols, flags = it.frames, it.which, it.corners, it.h, it.w, it.cols, it.flags
    rowval, colterm, cell_black, rts_sum, blink_extra = it.rowval, it.colterm, it.cell_black, it.rts_sum, it.blink_extra
    j, i, b = cuda.grid(3)
    if j >= w or i >= h or b >= frames.size:
        return
    p = which[b]
    po = it.offsets_of[b]  # the pixels' offsets' row (lines(), the same)
    has_noisy, has_exact, has_sf, has_row, has_col, adc_on, want_e = (
        flags[p, S_NOISY], flags[p, S_EXACT], flags[p, S_SF], flags[p, S_ROW], flags[p, S_COL], flags[p, S_ADC],
        flags[p, S_ELECTRONS])
    has_nl, has_offset, has_read = flags[p, S_NL], flags[p, S_OFFSET], flags[p, S_READ]
    has_rts, has_blink, blink_exact = flags[p, S_TRAPS], flags[p, S_BLINKERS], flags[p, S_BLINK_EXACT]
    r = corners[b, 0] + i
    c = corners[b, 1] + j
    fr = np.uint64(frames[b])
    sq = seqs[p]
    index = np.uint64(r * cols + c)
    blink = find(blink_ptr[p], blink_col, r, c) if has_blink else -1
    n = 0.0
    blink_mean = 0.0
    if blink >= 0:  # stage 4b: a blinking pixel's mean charge of this frame, float32 (telegraph.plus_charge)
        held = exact[p, r, c] if blink_exact else noisy[p, r, c]
        blink_mean = np.float64(np.float32(np.float64(held) + blink_extra[b, blink - blinks[p]]))
    if has_noisy:
        m = np.float64(noisy[p, r, c])
        if blink >= 0 and not blink_exact:  # a blinking pixel's count at this frame's mean
            m = blink_mean
        n = poisson_one(m, index, fr, sq, keys[p, KEY_SHOT, 0], keys[p, KEY_SHOT, 1], numbers[p, NORMAL_ABOVE])
    if has_exact:
        if blink >= 0 and blink_exact:  # a blinking pixel's mean dark charge of this frame
            n = n + blink_mean
        else:
            n = n + np.float64(exact[p, r, c])
    n = min(n, numbers[p, FULL_WELL])
    if has_nl:  # stage 5b (nonlinearity.Curve.apply)
        size = ints[p, NL_SIZE]
        if size > 2:
            q = n * numbers[p, NL_SCALE]
            t = np.int64(min(floor(q), np.float64(size - 2)))
            lo = nl_table[p, t]
            n = lo + (q - t) * (nl_table[p, t + 1] - lo)
        else:
            sx = n * numbers[p, NL_SCALE]
            n = n * (1.0 + sx * (numbers[p, NL_A] + sx * (numbers[p, NL_B] + sx * numbers[p, NL_C])))
    z = partner = 0.0
    if has_sf or has_read:  # the source follower's block: its cosine normal is stage 6's, its sine normal 9a's
        u1, u2 = uniform_pair(index, fr, sq, np.uint64(0), keys[p, KEY_SF, 0], keys[p, KEY_SF, 1])
        z, partner = normal_pair_from(u1, u2)
    if has_sf:
        noise = np.float64(sf[p, r, c]) * z
        if has_offset:
            n = (n + np.float64(offset[po, r, c])) + noise
        else:
            n = n + noise
    elif has_offset:  # stage 5c
        n = n + np.float64(offset[po, r, c])
    if has_rts:  # stage 6b
        e = find(rts_ptr[p], rts_col, r, c)
        if e >= 0:
            n = n + rts_sum[b, e - groups[p]]
    if has_row:
        n = n + rowval[b, i]
    if has_col:
        n = n * gain[p, c] + colterm[b, j]
    if want_e:
        out_e[b, i, j] = np.float32(n)
    if adc_on:
        v = n * numbers[p, K_ADC] + cell_black[b, 2 * (r & 1) + (c & 1)]
        if has_read:  # stage 9a
            scale = numbers[p, READ_SCALE]
            if ints[p, READ_KIND] == 0:
                noise = scale * partner
            else:
                kf, wt = tukey_lambda_cell(partner)
                noise = scale * tukey_lambda_at(read_table[p], kf, wt, partner)
            v = v + noise
        step = numbers[p, STEP]  # the ADC rounds its own codes (kernel._render_rows)
        v = rint(v * (1.0 / step))
        out_dn[b, i, j] = np.uint16(min(max(v, 0.0), numbers[p, TOP]) * step)


@cuda.jit(fastmath=False)
def stick(which, start, where, value, corners, out):
    """Stuck pixels (stage 15): ``out[b]`` at each of its plan's stuck pixels (``where``, full-frame (row, col),
    plan ``p``'s from ``start[p]`` to ``start[p + 1]``) inside the item."""
    s, b = cuda.grid(2)
    if b >= out.shape[0]:
        return
    p = which[b]
    q = start[p] + s
    if q >= start[p + 1]:
        return
    i = where[q, 0] - corners[b, 0]
    j = where[q, 1] - corners[b, 1]
    if 0 <= i < out.shape[1] and 0 <= j < out.shape[2]:
        out[b, i, j] = value[q]


@cuda.jit(fastmath=False)
def gather(source, corners, out):
    """``out[b] = source[r:r + h, c:c + w]`` at each item's corner ``(r, c) = corners[b]``: (B, h, w)."""
    j, i, b = cuda.grid(3)
    if b < out.shape[0] and i < out.shape[1] and j < out.shape[2]:
        out[b, i, j] = source[corners[b, 0] + i, corners[b, 1] + j]


# ------------------------------------------------------------------ fixed maps (fixed_maps' sources, per pixel)
ppf_cell, heavy_tail_value, two_point, normal_value, offset_value = (
    h[k] for k in ("ppf_cell", "heavy_tail_value", "two_point", "normal_value", "offset_value"))
_Z64, _ONE64 = np.uint64(0), np.uint64(1)


@cuda.jit(fastmath=False)
def normal_map(out, r0, c0, cols, k0, k1, mean, sigma, low):
    """kernel._normal_map on the device: one thread a pixel of the rectangle at (r0, c0)."""
    j, i = cuda.grid(2)
    if i < out.shape[0] and j < out.shape[1]:
        index = np.uint64(r0 + i) * cols + np.uint64(c0) + np.uint64(j)
        u1, u2 = uniform_pair(index, _Z64, _Z64, _Z64, k0, k1)
        out[i, j] = np.float32(normal_value(u1, u2, mean, sigma, low))


@cuda.jit(fastmath=False)
def offset_map(out, r0, c0, cols, k0, k1, sigma, fraction, tail_max):
    """kernel._offset_map on the device: one thread a pixel; block 1 (the tail) drawn only where the map has one."""
    j, i = cuda.grid(2)
    if i < out.shape[0] and j < out.shape[1]:
        index = np.uint64(r0 + i) * cols + np.uint64(c0) + np.uint64(j)
        out[i, j] = np.float32(offset_value(index, k0, k1, sigma, fraction, tail_max))


@cuda.jit(fastmath=False)
def heavy_tail_map(out, r0, c0, cols, k0, k1, start, step, last, tables, params, w, body_scale, tail_scale, two):
    """kernel._heavy_tail_map on the device: one thread a pixel; block 1 (the tail's magnitude) drawn only for the
    tail's members, as there."""
    j, i = cuda.grid(2)
    if i < out.shape[0] and j < out.shape[1]:
        bs = 1.0 if two else body_scale
        ts = 1.0 if two else tail_scale
        top = max(params[0, 0], params[1, 0]) if two else params[0, 0]
        index = np.uint64(r0 + i) * cols + np.uint64(c0) + np.uint64(j)
        u_body, u_member = uniform_pair(index, _Z64, _Z64, _Z64, k0, k1)
        node, weight = ppf_cell(u_body, start, step, last)
        u_tail = 0.5  # read only by the tail's members
        if u_member < top:
            u_tail, _ = uniform_pair(index, _Z64, _Z64, _ONE64, k0, k1)
        k = int(node)
        v = heavy_tail_value(tables[0, k], tables[0, k + 1], weight, u_member, u_tail, bs, params[0, 0],
                             params[0, 1], ts)
        if two:
            v1 = heavy_tail_value(tables[1, k], tables[1, k + 1], weight, u_member, u_tail, 1.0, params[1, 0],
                                  params[1, 1], 1.0)
            v = two_point(v, v1, params[0, 2], params[1, 2], w)
        out[i, j] = np.float32(v)
