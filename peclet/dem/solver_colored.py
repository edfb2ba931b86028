"""The coloured path of :mod:`peclet.dem.solver` (its docstring: when and why): the colouring
of a contact list (:func:`color_contacts`, :class:`Colored`), and the velocity solve and position
projection swept colour by colour, the contacts of one colour in parallel, the colours in
alternating order (:func:`sweep_colors`, one schedule for both). No two contacts of a colour
share a body, so each update reads and writes rows no other update of its colour touches: the
result is that of the serial sweep over the contacts in colour order, bit for bit, at any thread
count (docs/architecture.md §7).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numba.extending import overload

from peclet.dem.solver_position import (PosState, corrections, move_bodies, pos_setup_range,
                                        pos_sweep, raise_bad_turn)
from peclet.dem.solver_rows import COLOR_CHUNK, PARALLEL_COLOR_MIN, Rows
from peclet.dem.solver_velocity import VelState, vel_setup, vel_sweep, vn_after, warm_bodies
from peclet.dem.sorting import counting_sort

# bits of colour set per int64 word in color_contacts (the sign bit left alone)
_COLOR_BITS = 62


@njit(cache=True)
def color_contacts(ca, cb, n_bodies):
    """A colouring of the contacts (a[i], b[i]) (b < 0: a wall, which is no body) such that no
    two contacts of one colour share a body: greedy in contact order, each contact taking the
    lowest colour free at both its bodies (deterministic: a function of the contact list
    alone). Returns (order (n,), start (K + 1,), body_start (N + 1,), body_items): the
    contacts colour by colour, in contact order within a colour (colour k at
    ``order[start[k]:start[k + 1]]``), and for each body j the positions u in ``order`` of
    its contacts, ascending, at ``body_items[body_start[j]:body_start[j + 1]]``."""
    n = ca.shape[0]
    body_start = np.zeros(n_bodies + 1, np.int64)
    for i in range(n):
        body_start[ca[i] + 1] += 1
        if cb[i] >= 0:
            body_start[cb[i] + 1] += 1
    maxdeg = 0
    for j in range(n_bodies):
        maxdeg = max(maxdeg, body_start[j + 1])
        body_start[j + 1] += body_start[j]
    # a contact meets at most deg(a) - 1 + deg(b) - 1 coloured neighbours: 2 maxdeg colours
    # always suffice. Colour sets as bit words of _COLOR_BITS bits (int64, sign bit unused).
    words = (2 * maxdeg) // _COLOR_BITS + 1
    full = (np.int64(1) << _COLOR_BITS) - 1
    used = np.zeros((n_bodies, words), np.int64)
    color = np.empty(n, np.int64)
    ncol = np.int64(0)
    for i in range(n):
        a = ca[i]
        b = cb[i]
        c = -1
        for k in range(words):
            m = used[a, k]
            if b >= 0:
                m |= used[b, k]
            free = ~m & full
            if free != 0:
                bit = 0
                while (free >> bit) & 1 == 0:
                    bit += 1
                c = k * _COLOR_BITS + bit
                break
        color[i] = c
        k = c // _COLOR_BITS
        f = np.int64(1) << (c % _COLOR_BITS)
        used[a, k] |= f
        if b >= 0:
            used[b, k] |= f
        ncol = max(ncol, c + 1)
    start, order = counting_sort(color, ncol)
    body_fill = body_start[:-1].copy()
    body_items = np.empty(body_start[n_bodies], np.int64)
    for u in range(n):
        i = order[u]
        body_items[body_fill[ca[i]]] = u
        body_fill[ca[i]] += 1
        if cb[i] >= 0:
            body_items[body_fill[cb[i]]] = u
            body_fill[cb[i]] += 1
    return order, start, body_start, body_items


class Colored(NamedTuple):
    """A colouring of a contact list (:func:`color_contacts`): ``order`` (n,) the contacts
    colour by colour, ``start`` (K + 1,) each colour's first position in it, and for each body
    j its positions in ``order``, ascending, at ``body_items[body_start[j]:body_start[j +
    1]]``. The coloured solvers take the contacts rearranged into ``order``
    (:func:`peclet.dem.contacts.reorder`), so that a colour's contacts are contiguous."""
    order: np.ndarray
    start: np.ndarray
    body_start: np.ndarray
    body_items: np.ndarray


def sweep_range(c0, c1, backward, con, st, body):
    """One Gauss-Seidel pass over contacts c0..c1-1 of ``con`` (from the last when
    ``backward``): :func:`~peclet.dem.solver_velocity.vel_sweep` when ``st`` is a
    :class:`~peclet.dem.solver_velocity.VelState`,
    :func:`~peclet.dem.solver_position.pos_sweep` when it is a
    :class:`~peclet.dem.solver_position.PosState`. For kernels only: Numba picks the sweep from
    the type of ``st`` when it compiles the caller (the overload below)."""
    raise NotImplementedError("sweep_range is resolved inside Numba kernels only")


@overload(sweep_range)
def _sweep_range_for(c0, c1, backward, con, st, body):
    kind = getattr(st, "instance_class", None)
    if kind is VelState:
        def vel(c0, c1, backward, con, st, body):
            vel_sweep(c0, c1, backward, con, st, body)
        return vel
    if kind is PosState:
        def pos(c0, c1, backward, con, st, body):
            pos_sweep(c0, c1, backward, con, st, body)
        return pos
    return None


@njit(cache=True, parallel=True)
def sweep_colors(con, st, body, start, iterations):
    """``iterations`` passes of :func:`sweep_range` over the contacts of ``con`` (on the
    state ``st`` and the bodies' :class:`~peclet.dem.solver_rows.Rows` ``body``) given colour
    by colour (colour k: contacts ``start[k]`` to ``start[k + 1]``), the colours 0, 1, ... on
    even iterations and in reverse on odd ones; the contacts of a colour in parallel (chunks
    of ``COLOR_CHUNK``) from ``PARALLEL_COLOR_MIN`` contacts on, else in the calling thread.
    The tuples are flat (arrays and scalars): a parallel loop passes a named tuple's fields one
    by one, one level deep."""
    ncol = start.shape[0] - 1
    for it in range(iterations):
        back = it % 2 == 1
        for kk in range(ncol):
            k = ncol - 1 - kk if back else kk
            c0 = start[k]
            c1 = start[k + 1]
            if c1 - c0 < PARALLEL_COLOR_MIN:
                sweep_range(c0, c1, back, con, st, body)
            else:
                for ch in prange((c1 - c0 + COLOR_CHUNK - 1) // COLOR_CHUNK):
                    sweep_range(c0 + ch * COLOR_CHUNK, min(c1, c0 + (ch + 1) * COLOR_CHUNK),
                                back, con, st, body)


@njit(cache=True, parallel=True)
def solve_velocities_colored(con, lam, v, w, inv_mass, invI, dt, rest_threshold, slop,
                             iterations, colors):
    """:func:`~peclet.dem.solver_velocity.solve_velocities` on contacts given colour by colour
    (the :class:`Colored` ``colors``), swept by :func:`sweep_colors`. The warm start is applied
    body by body (``body_items[body_start[j]:body_start[j + 1]]``: body j's contacts in
    ascending order), each body's impulses added in contact order. The result is that of
    :func:`~peclet.dem.solver_velocity.solve_velocities` on the same contact list, bit for bit,
    at any thread count."""
    start, body_start, body_items = colors.start, colors.body_start, colors.body_items
    n = con.a.shape[0]
    nb = v.shape[0]
    body = Rows(v, w, inv_mass, invI)
    st = VelState(np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                  lam)
    for ch in prange((n + COLOR_CHUNK - 1) // COLOR_CHUNK):
        vel_setup(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), con, body, dt,
                  rest_threshold, slop, st)
    for ch in prange((nb + COLOR_CHUNK - 1) // COLOR_CHUNK):
        warm_bodies(ch * COLOR_CHUNK, min(nb, (ch + 1) * COLOR_CHUNK), body_start, body_items,
                    con, lam, body)
    sweep_colors(con, st, body, start, iterations)
    vn_out = np.empty(n)
    for ch in prange((n + COLOR_CHUNK - 1) // COLOR_CHUNK):
        vn_after(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), con, v, w, vn_out)
    return vn_out


@njit(cache=True, parallel=True)
def project_positions_colored(con, gap_end, inv_mass, invI, slop, iterations, pos, quats,
                              colors):
    """:func:`~peclet.dem.solver_position.project_positions` on contacts given colour by colour
    (the :class:`Colored` ``colors``), swept by :func:`sweep_colors`: the bits of the serial
    projection of that contact list, at any thread count."""
    start = colors.start
    n = con.a.shape[0]
    nb = pos.shape[0]
    kn = np.empty(n)
    nch = (n + COLOR_CHUNK - 1) // COLOR_CHUNK
    over = np.empty(nch, np.bool_)
    for ch in prange(nch):
        over[ch] = pos_setup_range(ch * COLOR_CHUNK, min(n, (ch + 1) * COLOR_CHUNK), con,
                                   gap_end, inv_mass, invI, slop, kn)
    if not over.any():
        return
    dx, dth, acc = corrections(n, nb)
    sweep_colors(con, PosState(gap_end, kn, acc, slop), Rows(dx, dth, inv_mass, invI), start,
                 iterations)
    nch = (nb + COLOR_CHUNK - 1) // COLOR_CHUNK
    bad = np.empty(nch, np.int64)
    for ch in prange(nch):
        bad[ch] = move_bodies(ch * COLOR_CHUNK, min(nb, (ch + 1) * COLOR_CHUNK), dx, dth, pos,
                              quats)
    for ch in range(nch):
        if bad[ch] >= 0:
            raise_bad_turn(bad[ch], dth, quats)
