"""Compiled (numba) loops over links: forward kinematics, Newton-Euler, CRBA and ABA.

All quantities are in the base frame (world axes, base origin), SI units.  The kernels
take the figure's arrays directly (see :class:`physanim.dynamics.figure.Figure`) and a
batch dimension ``B`` so that one call serves a whole trajectory or all columns of H.
Cross products and 3x3 products are written out by hand: numpy's generic routines cost
microseconds per call, which dominates at ~30 bodies.

CRBA and ABA use spatial vectors in absolute coordinates (Featherstone 2008, ch. 6-7):
every motion vector is (angular, linear velocity of the point at the base origin O) and
every force vector (moment about O, force), all on world axes, so a child's quantities add
to its parent's without a coordinate transform.  A joint's motion subspace is then
S = (z, p x z) for axis z through the joint position p.  The figure's constant arrays are
packed per link into one row of ``model`` (n, 22) to keep calls cheap: axis (3), offset
(3) m, mass kg, COM (3) m, inertia about the COM (9, row-major) kg m^2, all in the link
frame, and the capsule tip (3) m (:attr:`physanim.dynamics.figure.Figure.packed`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def _axis_angle(ax, ay, az, angle):
    """Entries (row by row) of the rotation by ``angle`` rad about the unit axis (Rodrigues)."""
    c = math.cos(angle)
    s = math.sin(angle)
    v = 1.0 - c
    return (
        c + ax * ax * v, ax * ay * v - az * s, ax * az * v + ay * s,
        ay * ax * v + az * s, c + ay * ay * v, ay * az * v - ax * s,
        az * ax * v - ay * s, az * ay * v + ax * s, c + az * az * v,
    )  # fmt: skip


@njit(cache=True)
def fk_one(parent, axis, offset, q, base_pos, base_rot, rot, pos):
    """Joint frames for one pose: ``rot`` (n, 3, 3) and ``pos`` (n, 3) filled in place."""
    n = parent.shape[0]
    for i in range(n):
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _axis_angle(
            axis[i, 0], axis[i, 1], axis[i, 2], q[i]
        )
        p = parent[i]
        rp = base_rot if p < 0 else rot[p]
        for k in range(3):
            a0, a1, a2 = rp[k, 0], rp[k, 1], rp[k, 2]
            rot[i, k, 0] = a0 * r00 + a1 * r10 + a2 * r20
            rot[i, k, 1] = a0 * r01 + a1 * r11 + a2 * r21
            rot[i, k, 2] = a0 * r02 + a1 * r12 + a2 * r22
            o = a0 * offset[i, 0] + a1 * offset[i, 1] + a2 * offset[i, 2]
            pos[i, k] = (base_pos[k] if p < 0 else pos[p, k]) + o


@njit(cache=True)
def fk_batch(parent, axis, offset, q, base_pos, base_rot):
    """Frames for a batch: q (B, n), base_pos (B, 3) -> rot (B, n, 3, 3), pos (B, n, 3)."""
    nb, n = q.shape
    rot = np.empty((nb, n, 3, 3))
    pos = np.empty((nb, n, 3))
    for b in range(nb):
        fk_one(parent, axis, offset, q[b], base_pos[b], base_rot, rot[b], pos[b])
    return rot, pos


@njit(cache=True)
def rnea_batch(parent, axis, offset, mass, com, inertia, tip, q, qd, qdd, a0, fext):
    """Recursive Newton-Euler (Luh-Walker-Paul) joint torques, N m.

    q, qd, qdd: (B, n) rad, rad/s, rad/s^2; a0: (B, 3) base acceleration minus gravity,
    m/s^2; fext: (B, n, 6) force (N) and moment (N m) exerted on each link at its tip
    ``tip`` (n, 3) (link frame).  Returns tau (B, n).
    """
    nb, n = q.shape
    tau = np.empty((nb, n))
    rot = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    z = np.empty((n, 3))
    w = np.empty((n, 3))
    al = np.empty((n, 3))
    acc = np.empty((n, 3))
    f = np.empty((n, 3))
    mo = np.empty((n, 3))
    zero3 = np.zeros(3)
    eye = np.eye(3)
    for b in range(nb):
        fk_one(parent, axis, offset, q[b], zero3, eye, rot, pos)
        for i in range(n):
            p = parent[i]
            r = rot[i]
            zx = r[0, 0] * axis[i, 0] + r[0, 1] * axis[i, 1] + r[0, 2] * axis[i, 2]
            zy = r[1, 0] * axis[i, 0] + r[1, 1] * axis[i, 1] + r[1, 2] * axis[i, 2]
            zz = r[2, 0] * axis[i, 0] + r[2, 1] * axis[i, 1] + r[2, 2] * axis[i, 2]
            z[i, 0], z[i, 1], z[i, 2] = zx, zy, zz
            if p < 0:
                wpx = wpy = wpz = 0.0
                apx = apy = apz = 0.0
                lx, ly, lz = a0[b, 0], a0[b, 1], a0[b, 2]
                rx, ry, rz = pos[i, 0], pos[i, 1], pos[i, 2]
            else:
                wpx, wpy, wpz = w[p, 0], w[p, 1], w[p, 2]
                apx, apy, apz = al[p, 0], al[p, 1], al[p, 2]
                lx, ly, lz = acc[p, 0], acc[p, 1], acc[p, 2]
                rx, ry, rz = pos[i, 0] - pos[p, 0], pos[i, 1] - pos[p, 1], pos[i, 2] - pos[p, 2]
            # origin acceleration: a_p + alpha_p x r + w_p x (w_p x r)
            t1 = _cross(apx, apy, apz, rx, ry, rz)
            t2 = _cross(wpx, wpy, wpz, rx, ry, rz)
            t3 = _cross(wpx, wpy, wpz, t2[0], t2[1], t2[2])
            acc[i, 0] = lx + t1[0] + t3[0]
            acc[i, 1] = ly + t1[1] + t3[1]
            acc[i, 2] = lz + t1[2] + t3[2]
            v = qd[b, i]
            dv = qdd[b, i]
            wx, wy, wz = wpx + zx * v, wpy + zy * v, wpz + zz * v
            t4 = _cross(wpx, wpy, wpz, zx * v, zy * v, zz * v)
            alx = apx + zx * dv + t4[0]
            aly = apy + zy * dv + t4[1]
            alz = apz + zz * dv + t4[2]
            w[i, 0], w[i, 1], w[i, 2] = wx, wy, wz
            al[i, 0], al[i, 1], al[i, 2] = alx, aly, alz
            # COM offset (world) and acceleration
            cx = r[0, 0] * com[i, 0] + r[0, 1] * com[i, 1] + r[0, 2] * com[i, 2]
            cy = r[1, 0] * com[i, 0] + r[1, 1] * com[i, 1] + r[1, 2] * com[i, 2]
            cz = r[2, 0] * com[i, 0] + r[2, 1] * com[i, 1] + r[2, 2] * com[i, 2]
            t5 = _cross(alx, aly, alz, cx, cy, cz)
            t6 = _cross(wx, wy, wz, cx, cy, cz)
            t7 = _cross(wx, wy, wz, t6[0], t6[1], t6[2])
            m = mass[i]
            fx = m * (acc[i, 0] + t5[0] + t7[0])
            fy = m * (acc[i, 1] + t5[1] + t7[1])
            fz = m * (acc[i, 2] + t5[2] + t7[2])
            # N = R I R^T alpha + w x (R I R^T w)
            ii = inertia[i]
            ua = (
                r[0, 0] * alx + r[1, 0] * aly + r[2, 0] * alz,
                r[0, 1] * alx + r[1, 1] * aly + r[2, 1] * alz,
                r[0, 2] * alx + r[1, 2] * aly + r[2, 2] * alz,
            )
            uw = (
                r[0, 0] * wx + r[1, 0] * wy + r[2, 0] * wz,
                r[0, 1] * wx + r[1, 1] * wy + r[2, 1] * wz,
                r[0, 2] * wx + r[1, 2] * wy + r[2, 2] * wz,
            )
            ia0 = ii[0, 0] * ua[0] + ii[0, 1] * ua[1] + ii[0, 2] * ua[2]
            ia1 = ii[1, 0] * ua[0] + ii[1, 1] * ua[1] + ii[1, 2] * ua[2]
            ia2 = ii[2, 0] * ua[0] + ii[2, 1] * ua[1] + ii[2, 2] * ua[2]
            iw0 = ii[0, 0] * uw[0] + ii[0, 1] * uw[1] + ii[0, 2] * uw[2]
            iw1 = ii[1, 0] * uw[0] + ii[1, 1] * uw[1] + ii[1, 2] * uw[2]
            iw2 = ii[2, 0] * uw[0] + ii[2, 1] * uw[1] + ii[2, 2] * uw[2]
            gx = r[0, 0] * iw0 + r[0, 1] * iw1 + r[0, 2] * iw2
            gy = r[1, 0] * iw0 + r[1, 1] * iw1 + r[1, 2] * iw2
            gz = r[2, 0] * iw0 + r[2, 1] * iw1 + r[2, 2] * iw2
            t8 = _cross(wx, wy, wz, gx, gy, gz)
            t9 = _cross(cx, cy, cz, fx, fy, fz)
            # external load at the tip
            tx = r[0, 0] * tip[i, 0] + r[0, 1] * tip[i, 1] + r[0, 2] * tip[i, 2]
            ty = r[1, 0] * tip[i, 0] + r[1, 1] * tip[i, 1] + r[1, 2] * tip[i, 2]
            tz = r[2, 0] * tip[i, 0] + r[2, 1] * tip[i, 1] + r[2, 2] * tip[i, 2]
            ef = fext[b, i]
            t10 = _cross(tx, ty, tz, ef[0], ef[1], ef[2])
            f[i, 0] = fx - ef[0]
            f[i, 1] = fy - ef[1]
            f[i, 2] = fz - ef[2]
            mo[i, 0] = (
                r[0, 0] * ia0 + r[0, 1] * ia1 + r[0, 2] * ia2 + t8[0] + t9[0] - t10[0] - ef[3]
            )
            mo[i, 1] = (
                r[1, 0] * ia0 + r[1, 1] * ia1 + r[1, 2] * ia2 + t8[1] + t9[1] - t10[1] - ef[4]
            )
            mo[i, 2] = (
                r[2, 0] * ia0 + r[2, 1] * ia1 + r[2, 2] * ia2 + t8[2] + t9[2] - t10[2] - ef[5]
            )
        for i in range(n - 1, -1, -1):
            tau[b, i] = z[i, 0] * mo[i, 0] + z[i, 1] * mo[i, 1] + z[i, 2] * mo[i, 2]
            p = parent[i]
            if p >= 0:
                rx, ry, rz = pos[i, 0] - pos[p, 0], pos[i, 1] - pos[p, 1], pos[i, 2] - pos[p, 2]
                t11 = _cross(rx, ry, rz, f[i, 0], f[i, 1], f[i, 2])
                for k in range(3):
                    f[p, k] += f[i, k]
                    mo[p, k] += mo[i, k] + t11[k]
    return tau


@njit(cache=True, inline="always")
def _body_inertia(model, i, r, px, py, pz, out):
    """World spatial inertia of link i about O, (6, 6), into ``out``; r: link rotation.

    [[J_O, [h]x], [[h]x^T, m E]] with h = m c (c: world COM) and J_O the rotational
    inertia about O (parallel-axis term included).
    """
    m = model[i, 6]
    lx, ly, lz = model[i, 7], model[i, 8], model[i, 9]
    cx = px + r[0, 0] * lx + r[0, 1] * ly + r[0, 2] * lz
    cy = py + r[1, 0] * lx + r[1, 1] * ly + r[1, 2] * lz
    cz = pz + r[2, 0] * lx + r[2, 1] * ly + r[2, 2] * lz
    # R I R^T (symmetric): rows of R I first
    i00, i01, i02 = model[i, 10], model[i, 11], model[i, 12]
    i10, i11, i12 = model[i, 13], model[i, 14], model[i, 15]
    i20, i21, i22 = model[i, 16], model[i, 17], model[i, 18]
    for k in range(3):
        a0 = r[k, 0] * i00 + r[k, 1] * i10 + r[k, 2] * i20
        a1 = r[k, 0] * i01 + r[k, 1] * i11 + r[k, 2] * i21
        a2 = r[k, 0] * i02 + r[k, 1] * i12 + r[k, 2] * i22
        for c in range(k, 3):
            v = a0 * r[c, 0] + a1 * r[c, 1] + a2 * r[c, 2]
            out[k, c] = v
            out[c, k] = v
    cc = cx * cx + cy * cy + cz * cz
    out[0, 0] += m * (cc - cx * cx)
    out[1, 1] += m * (cc - cy * cy)
    out[2, 2] += m * (cc - cz * cz)
    out[0, 1] -= m * cx * cy
    out[1, 0] -= m * cx * cy
    out[0, 2] -= m * cx * cz
    out[2, 0] -= m * cx * cz
    out[1, 2] -= m * cy * cz
    out[2, 1] -= m * cy * cz
    hx, hy, hz = m * cx, m * cy, m * cz
    # upper right [h]x, lower left its transpose, lower right m E
    out[0, 3], out[0, 4], out[0, 5] = 0.0, -hz, hy
    out[1, 3], out[1, 4], out[1, 5] = hz, 0.0, -hx
    out[2, 3], out[2, 4], out[2, 5] = -hy, hx, 0.0
    for k in range(3):
        for c in range(3):
            out[3 + k, c] = out[c, 3 + k]
            out[3 + k, 3 + c] = m if k == c else 0.0


@njit(cache=True, inline="always")
def _frames(parent, model, q, rot, pos, s):
    """Joint frames (rot (n, 3, 3), pos (n, 3), base at O) and motion subspaces s (n, 6)."""
    n = parent.shape[0]
    for i in range(n):
        ax, ay, az = model[i, 0], model[i, 1], model[i, 2]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _axis_angle(ax, ay, az, q[i])
        p = parent[i]
        ox, oy, oz = model[i, 3], model[i, 4], model[i, 5]
        if p < 0:  # the base frame is the world frame
            rot[i, 0, 0], rot[i, 0, 1], rot[i, 0, 2] = r00, r01, r02
            rot[i, 1, 0], rot[i, 1, 1], rot[i, 1, 2] = r10, r11, r12
            rot[i, 2, 0], rot[i, 2, 1], rot[i, 2, 2] = r20, r21, r22
            pos[i, 0], pos[i, 1], pos[i, 2] = ox, oy, oz
            # the axis is fixed in the parent (here the base) frame
            zx, zy, zz = ax, ay, az
        else:
            for k in range(3):
                a0, a1, a2 = rot[p, k, 0], rot[p, k, 1], rot[p, k, 2]
                rot[i, k, 0] = a0 * r00 + a1 * r10 + a2 * r20
                rot[i, k, 1] = a0 * r01 + a1 * r11 + a2 * r21
                rot[i, k, 2] = a0 * r02 + a1 * r12 + a2 * r22
                pos[i, k] = pos[p, k] + a0 * ox + a1 * oy + a2 * oz
            zx = rot[p, 0, 0] * ax + rot[p, 0, 1] * ay + rot[p, 0, 2] * az
            zy = rot[p, 1, 0] * ax + rot[p, 1, 1] * ay + rot[p, 1, 2] * az
            zz = rot[p, 2, 0] * ax + rot[p, 2, 1] * ay + rot[p, 2, 2] * az
        s[i, 0], s[i, 1], s[i, 2] = zx, zy, zz
        m = _cross(pos[i, 0], pos[i, 1], pos[i, 2], zx, zy, zz)
        s[i, 3], s[i, 4], s[i, 5] = m[0], m[1], m[2]


@njit(cache=True)
def crba(parent, model, q):
    """Joint-space inertia matrix H (n, n), kg m^2, by composite rigid bodies; q (n,) rad.

    Composite spatial inertias about O are summed from the leaves; H[j, i] = S_j . (I_i S_i)
    for every ancestor j of i.  Links with zero mass but non-zero rotational inertia count.
    """
    n = parent.shape[0]
    rot = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    s = np.empty((n, 6))
    ic = np.empty((n, 6, 6))
    _frames(parent, model, q, rot, pos, s)
    for i in range(n):
        _body_inertia(model, i, rot[i], pos[i, 0], pos[i, 1], pos[i, 2], ic[i])
    for i in range(n - 1, -1, -1):
        p = parent[i]
        if p >= 0:
            for k in range(6):
                for c in range(6):
                    ic[p, k, c] += ic[i, k, c]
    hm = np.zeros((n, n))
    f = np.empty(6)
    for i in range(n):
        for k in range(6):
            f[k] = (
                ic[i, k, 0] * s[i, 0]
                + ic[i, k, 1] * s[i, 1]
                + ic[i, k, 2] * s[i, 2]
                + ic[i, k, 3] * s[i, 3]
                + ic[i, k, 4] * s[i, 4]
                + ic[i, k, 5] * s[i, 5]
            )
        j = i
        while j >= 0:
            val = (
                s[j, 0] * f[0]
                + s[j, 1] * f[1]
                + s[j, 2] * f[2]
                + s[j, 3] * f[3]
                + s[j, 4] * f[4]
                + s[j, 5] * f[5]
            )
            hm[j, i] = val
            hm[i, j] = val
            j = parent[j]
    return hm


@njit(cache=True)
def aba(parent, model, q, qd, tau, a0, fext):
    """Forward dynamics qdd (n,) rad/s^2 by the articulated-body algorithm, O(n).

    q, qd, tau: (n,) rad, rad/s, N m; a0 (3,) base acceleration minus gravity, m/s^2;
    fext (n, 6) force (N) and moment (N m) on each link at its tip, world axes (as in
    :func:`rnea_batch`).  An empty (0,) tau or (0, 6) fext means zeros.  Featherstone's
    three passes in absolute coordinates.
    """
    n = parent.shape[0]
    work = np.empty(n * 89 + 12)  # one allocation for all work arrays (views below)
    rot = work[: 9 * n].reshape((n, 3, 3))
    pos = work[9 * n : 12 * n].reshape((n, 3))
    s = work[12 * n : 18 * n].reshape((n, 6))
    ia = work[18 * n : 54 * n].reshape((n, 6, 6))  # articulated inertias
    pa = work[54 * n : 60 * n].reshape((n, 6))  # articulated bias forces
    v = work[60 * n : 66 * n].reshape((n, 6))  # spatial velocities
    c = work[66 * n : 72 * n].reshape((n, 6))  # velocity-product accelerations
    u_vec = work[72 * n : 78 * n].reshape((n, 6))  # U = I^A S
    acc_b = work[78 * n : 84 * n].reshape((n, 6))  # body accelerations
    d_inv = work[84 * n : 85 * n]
    u_sc = work[85 * n : 86 * n]  # tau - S . p^A
    iv = work[89 * n : 89 * n + 6]
    ap = work[89 * n + 6 : 89 * n + 12]
    has_tau = tau.shape[0] > 0
    has_ext = fext.shape[0] > 0
    _frames(parent, model, q, rot, pos, s)
    for i in range(n):
        p = parent[i]
        w = qd[i]
        r = rot[i]
        vj0, vj1, vj2 = s[i, 0] * w, s[i, 1] * w, s[i, 2] * w
        vj3, vj4, vj5 = s[i, 3] * w, s[i, 4] * w, s[i, 5] * w
        if p < 0:
            v[i, 0], v[i, 1], v[i, 2], v[i, 3], v[i, 4], v[i, 5] = vj0, vj1, vj2, vj3, vj4, vj5
            for k in range(6):
                c[i, k] = 0.0
        else:
            # c = v_p x vJ (motion cross product)
            t1 = _cross(v[p, 0], v[p, 1], v[p, 2], vj0, vj1, vj2)
            t2 = _cross(v[p, 0], v[p, 1], v[p, 2], vj3, vj4, vj5)
            t3 = _cross(v[p, 3], v[p, 4], v[p, 5], vj0, vj1, vj2)
            c[i, 0], c[i, 1], c[i, 2] = t1[0], t1[1], t1[2]
            c[i, 3], c[i, 4], c[i, 5] = t2[0] + t3[0], t2[1] + t3[1], t2[2] + t3[2]
            v[i, 0], v[i, 1], v[i, 2] = v[p, 0] + vj0, v[p, 1] + vj1, v[p, 2] + vj2
            v[i, 3], v[i, 4], v[i, 5] = v[p, 3] + vj3, v[p, 4] + vj4, v[p, 5] + vj5
        _body_inertia(model, i, r, pos[i, 0], pos[i, 1], pos[i, 2], ia[i])
        for k in range(6):
            iv[k] = (
                ia[i, k, 0] * v[i, 0]
                + ia[i, k, 1] * v[i, 1]
                + ia[i, k, 2] * v[i, 2]
                + ia[i, k, 3] * v[i, 3]
                + ia[i, k, 4] * v[i, 4]
                + ia[i, k, 5] * v[i, 5]
            )
        # p^A = v x* (I v) - f_ext; the tip load as a spatial force about O
        n1 = _cross(v[i, 0], v[i, 1], v[i, 2], iv[0], iv[1], iv[2])
        n2 = _cross(v[i, 3], v[i, 4], v[i, 5], iv[3], iv[4], iv[5])
        f1 = _cross(v[i, 0], v[i, 1], v[i, 2], iv[3], iv[4], iv[5])
        pa[i, 0], pa[i, 1], pa[i, 2] = n1[0] + n2[0], n1[1] + n2[1], n1[2] + n2[2]
        pa[i, 3], pa[i, 4], pa[i, 5] = f1[0], f1[1], f1[2]
        if has_ext:
            tx = pos[i, 0] + r[0, 0] * model[i, 19] + r[0, 1] * model[i, 20]
            ty = pos[i, 1] + r[1, 0] * model[i, 19] + r[1, 1] * model[i, 20]
            tz = pos[i, 2] + r[2, 0] * model[i, 19] + r[2, 1] * model[i, 20]
            tx += r[0, 2] * model[i, 21]
            ty += r[1, 2] * model[i, 21]
            tz += r[2, 2] * model[i, 21]
            ef = fext[i]
            em = _cross(tx, ty, tz, ef[0], ef[1], ef[2])
            pa[i, 0] -= em[0] + ef[3]
            pa[i, 1] -= em[1] + ef[4]
            pa[i, 2] -= em[2] + ef[5]
            pa[i, 3] -= ef[0]
            pa[i, 4] -= ef[1]
            pa[i, 5] -= ef[2]
    for i in range(n - 1, -1, -1):
        si = s[i]
        for k in range(6):
            u_vec[i, k] = (
                ia[i, k, 0] * si[0]
                + ia[i, k, 1] * si[1]
                + ia[i, k, 2] * si[2]
                + ia[i, k, 3] * si[3]
                + ia[i, k, 4] * si[4]
                + ia[i, k, 5] * si[5]
            )
        uu = u_vec[i]
        dd = si[0] * uu[0] + si[1] * uu[1] + si[2] * uu[2] + si[3] * uu[3] + si[4] * uu[4]
        dd += si[5] * uu[5]
        d_inv[i] = 1.0 / dd
        u_sc[i] = (tau[i] if has_tau else 0.0) - (
            si[0] * pa[i, 0]
            + si[1] * pa[i, 1]
            + si[2] * pa[i, 2]
            + si[3] * pa[i, 3]
            + si[4] * pa[i, 4]
            + si[5] * pa[i, 5]
        )
        p = parent[i]
        if p < 0:
            continue
        # I^a = I^A - U U^T / D;  p^a = p^A + I^a c + U u / D; both added to the parent
        ci = c[i]
        ud = u_sc[i] * d_inv[i]
        for k in range(6):
            gk = uu[k] * d_inv[i]
            acc = 0.0
            for m in range(6):
                val = ia[i, k, m] - gk * uu[m]
                ia[p, k, m] += val
                acc += val * ci[m]
            pa[p, k] += pa[i, k] + acc + uu[k] * ud
    qdd = np.empty(n)
    for i in range(n):
        p = parent[i]
        if p < 0:
            ap[0], ap[1], ap[2] = c[i, 0], c[i, 1], c[i, 2]
            ap[3], ap[4], ap[5] = a0[0] + c[i, 3], a0[1] + c[i, 4], a0[2] + c[i, 5]
        else:
            for k in range(6):
                ap[k] = acc_b[p, k] + c[i, k]
        uu = u_vec[i]
        x = (
            u_sc[i]
            - uu[0] * ap[0]
            - uu[1] * ap[1]
            - uu[2] * ap[2]
            - uu[3] * ap[3]
            - uu[4] * ap[4]
            - uu[5] * ap[5]
        ) * d_inv[i]
        qdd[i] = x
        for k in range(6):
            acc_b[i, k] = ap[k] + s[i, k] * x
    return qdd
