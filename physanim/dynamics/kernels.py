"""Compiled (numba) loops over links: forward kinematics, recursive Newton-Euler, CRBA.

All quantities are in the base frame (world axes, base origin), SI units.  The kernels
take the figure's arrays directly (see :class:`physanim.dynamics.figure.Figure`) and a
batch dimension ``B`` so that one call serves a whole trajectory or all columns of H.
Cross products and 3x3 products are written out by hand: numpy's generic routines cost
microseconds per call, which dominates at ~30 bodies.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True)
def fk_one(parent, axis, offset, q, base_pos, base_rot, rot, pos):
    """Joint frames for one pose: ``rot`` (n, 3, 3) and ``pos`` (n, 3) filled in place."""
    n = parent.shape[0]
    for i in range(n):
        ax, ay, az = axis[i, 0], axis[i, 1], axis[i, 2]
        c = math.cos(q[i])
        s = math.sin(q[i])
        v = 1.0 - c
        r00 = c + ax * ax * v
        r01 = ax * ay * v - az * s
        r02 = ax * az * v + ay * s
        r10 = ay * ax * v + az * s
        r11 = c + ay * ay * v
        r12 = ay * az * v - ax * s
        r20 = az * ax * v - ay * s
        r21 = az * ay * v + ax * s
        r22 = c + az * az * v
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


@njit(cache=True)
def crba(parent, axis, offset, mass, com, inertia, q):
    """Joint-space inertia matrix H (n, n), kg m^2, by composite rigid bodies; q (n,) rad."""
    n = parent.shape[0]
    rot = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    fk_one(parent, axis, offset, q, np.zeros(3), np.eye(3), rot, pos)
    cm = mass.copy()  # composite mass
    h = np.empty((n, 3))  # composite first moment about the base origin, kg m
    jj = np.empty((n, 3, 3))  # composite inertia about the base origin, kg m^2
    for i in range(n):
        c = rot[i] @ com[i] + pos[i]
        iw = rot[i] @ inertia[i] @ rot[i].T
        cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        for k in range(3):
            h[i, k] = mass[i] * c[k]
            for m in range(3):
                jj[i, k, m] = iw[k, m] - mass[i] * c[k] * c[m]
            jj[i, k, k] += mass[i] * cc
    for i in range(n - 1, -1, -1):
        p = parent[i]
        if p >= 0:
            cm[p] += cm[i]
            h[p] += h[i]
            jj[p] += jj[i]
    hm = np.zeros((n, n))
    for i in range(n):
        zi = rot[i] @ axis[i]
        if cm[i] <= 0.0:
            continue
        c = h[i] / cm[i]
        cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        ic = jj[i].copy()
        for k in range(3):
            for m in range(3):
                ic[k, m] += cm[i] * c[k] * c[m]
            ic[k, k] -= cm[i] * cc
        d = c - pos[i]
        fv = _cross(zi[0], zi[1], zi[2], d[0], d[1], d[2])
        fx, fy, fz = cm[i] * fv[0], cm[i] * fv[1], cm[i] * fv[2]
        nv = ic @ zi
        j = i
        while j >= 0:
            zj = rot[j] @ axis[j]
            e = c - pos[j]
            t = _cross(e[0], e[1], e[2], fx, fy, fz)
            val = zj[0] * (nv[0] + t[0]) + zj[1] * (nv[1] + t[1]) + zj[2] * (nv[2] + t[2])
            hm[j, i] = val
            hm[i, j] = val
            j = parent[j]
    return hm
