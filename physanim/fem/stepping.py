"""Newmark substeps between capture frames (fixed, or adaptive) and the state they start from.

Adaptive frames take n substeps (n = 1, 2, 4, ...) and estimate the frame's local error in
displacement, either

- 'acceleration' (default): Zienkiewicz & Xie's a posteriori estimate for Newmark,
  e = -(beta - 1/6) h^2 (a_{k+1} - a_k) = -h^2/12 Delta a per substep, summed over the frame
  (the accelerations' change over it), taken through the step's matrix and with the driven
  nodes' path between the substeps (``Newmark.local_error_rhs``): one more solve per frame.
  The change is taken between substep-centred accelerations, (a + a_previous substep) / 2 at
  each end of the frame: stiff modes (omega h >> 1) ring at the step's Nyquist rate under this
  scheme (its amplification tends to -1 there), which a raw Delta a reads as an error of
  twice the ringing's size in frames of odd substep counts and cancels in even ones. Halving
  the step does not remove that ringing, so counting it only bought frames of 2 substeps that
  passed by the cancellation: on six of seven demo meshes 95-101 steps and a second
  factorisation; on one of them 95 steps against 89 now, both 0.614 % of the peak from the
  dt = 0.5 ms reference. In a ramp-and-hold test (tests/fem/test_fem_simulate.py) the raw
  estimate left the result 2.8 times over its 0.1 um tolerance; the centred one refines the
  start and meets it. Neither resolves lightly damped modes far above the frame rate (a slab
  at 1 % of the tissue's viscosity stays 2-3 times over a 1 um tolerance with either); or
- 'doubling': the frame is computed from the same state in n and 2n substeps, the finer kept
  and its error estimated as |d_2n - d_n| / (r^2 - 1) (Richardson, second order).

A frame over the tolerance is redone with twice the substeps; a frame far below it lets the
next one try half (the frame's error scales as h^2: n substeps of local error ~ h^3).

The 'acceleration' estimate's solve goes together with the next frame's first substep at the
same step size, in one solve call: kept when the frame is accepted and the step size stays,
which is most frames. At the coarsest step size a frame's estimate can only reject it (there
is no coarser size to try), so there the estimates wait: the frames go on, each with its own
step solve, and up to ``ERROR_BATCH`` estimates are solved together with the next frame's
first substep. PARDISO sweeps its factor once per column for two columns but blocks larger
sets (2 mm demo mesh, float32 factor: 1 column 33 ms, 2 columns 68 ms, 8 columns 93-102 ms);
the 2 mm demo's stepping went from 8.2 to 6.3 s. A frame over the tolerance rewinds the run
to it (``FrameStepper.redo``): the frames after it are discarded and it is redone finer, as
without the wait; the batch then restarts at one frame and doubles while its frames pass.
Waiting frames are recorded, and checked for an energy blow-up, before their estimates are
known: only the linear kinematics step adaptively, and for them the average-acceleration
scheme is unconditionally stable, so a coarse step cannot trip the check where a finer one
would pass.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from physanim.fem.boundary import BoundaryConditions, FrameForce
from physanim.fem.newmark import Newmark, State
from physanim.fem.params import SimulateParams
from physanim.fem.statics import solve_static

#: most error estimates of frames at the coarsest step size solved in one batch (module docstring)
ERROR_BATCH = 8


class SimulationDiverged(RuntimeError):
    """The time integration produced NaN/Inf or an exploding energy."""


def substep_levels(frame_dt: float, params: SimulateParams, adaptive_ok: bool) -> list[int]:
    """Substeps per frame to choose from: [n_max] when fixed, else 1, 2, 4, ... and n_max
    (n_max = ceil(frame_dt / params.dt)); 'doubling' frames pair level i and i + 1."""
    n_max = max(1, math.ceil(frame_dt / params.dt - 1e-9))
    if not (params.stepping == "adaptive" and adaptive_ok and n_max > 1):
        return [n_max]
    return sorted({min(2**i, n_max) for i in range(n_max.bit_length() + 1)})


def initial_state(
    integ: Newmark, bc: BoundaryConditions, force: FrameForce | None, solver: str
) -> State:
    """The state at frame 0: static equilibrium (``integ``'s stiffness) for the first
    prescribed displacements and applied forces (springs, actuation), the prescribed velocity
    and acceleration, and the free DOFs' acceleration from the equation of motion when
    anything moves."""
    n_dofs, pres = integ.M.shape[0], bc.prescribed_dofs
    state = State.rest(n_dofs)
    d_c, v_c, a_c = (x[0] for x in bc.prescribed(np.zeros(1)))
    f0 = None if force is None else force.full(0.0, n_dofs)
    loaded = f0 is not None and bool(np.any(f0))
    if np.any(d_c) or loaded:
        state.d[:] = solve_static(integ.K, pres, d_c, f0, solver=solver)
    state.v[pres], state.a[pres] = v_c, a_c
    if np.any(v_c) or np.any(a_c) or loaded:
        integ.initial_acceleration(state, f0)
    return state


class IntegratorCache:
    """Newmark integrators by substeps per frame; the least recently used beyond ``size``
    is dropped (its factor freed). ``seconds``: time spent factorising after the first."""

    def __init__(self, first: Newmark, n_sub: int, frame_dt: float, size: int) -> None:
        self._items: OrderedDict[int, Newmark] = OrderedDict({n_sub: first})
        self._template, self._frame_dt, self._size = first, frame_dt, size
        self.seconds = 0.0

    def get(self, n_sub: int) -> Newmark:
        if n_sub in self._items:
            self._items.move_to_end(n_sub)
            return self._items[n_sub]
        t0 = time.perf_counter()
        integ = self._template.with_dt(self._frame_dt / n_sub)
        self.seconds += time.perf_counter() - t0
        self._items[n_sub] = integ
        while len(self._items) > self._size:
            self._items.popitem(last=False)
        return integ


@dataclass
class _Waiting:
    """A frame stepped at the coarsest step size whose error estimate is not solved yet."""

    k: int
    before: tuple[np.ndarray, np.ndarray, np.ndarray]  # the state's d, v, a before frame k
    a_before: np.ndarray | None  # FrameStepper._a_before before frame k
    rhs: np.ndarray  # (n_free,) the estimate's right-hand side


class FrameStepper:
    """Advances a :class:`State` from frame k - 1 to frame k under boundary conditions ``bc``
    and optional applied ``force`` (springs, actuation). ``estimate``: 'acceleration' or
    'doubling' (module docstring). Counts per run: ``substeps`` (T,) substeps that led to each
    frame, ``check_steps`` (steps computed and discarded), ``over`` (frames whose error stayed
    above the tolerance at the smallest step allowed).

    After each ``frame`` call: ``redo`` is None, or the frame the run was rewound to (the
    state is then the one that frame starts from: step it next, then the frames after it
    again); ``solves`` is the number of single-column solves the call made, or 0 when its
    work is not comparable to a frame's (it solved a batch of waiting estimates, or its
    first substep had been solved with one)."""

    def __init__(
        self,
        integrators: IntegratorCache,
        levels: list[int],
        bc: BoundaryConditions,
        force: FrameForce | None,
        error_tol_m: float,
        estimate: str = "acceleration",
    ) -> None:
        self.integrators, self.levels, self.bc, self.force = integrators, levels, bc, force
        self.tol, self.estimate = error_tol_m, estimate
        self.level = 0
        self.substeps = np.zeros(bc.n_frames, dtype=np.int64)
        self.check_steps = 0
        self.over = 0
        #: (frame, substeps, solve (n_free,)) of the first substep of the frame after the one
        #: last estimated, solved with its estimate, from the state that frame ended in
        self._ahead: tuple[int, int, np.ndarray] | None = None
        #: free accelerations (n_free,) one substep before the state's time (None at frame 0),
        #: and those of the frame last estimated, made the former when it is accepted
        self._a_before: np.ndarray | None = None
        self._a_last: np.ndarray | None = None
        #: the last ``_drive`` made, by (frame, substeps): the next frame's first substep
        #: reads it, then that frame's steps
        self._last_drive: tuple[tuple[int, int], tuple[np.ndarray, ...]] | None = None
        #: frames whose estimates wait for a batched solve, and how many may wait now
        self._waiting: list[_Waiting] = []
        self._batch = 1
        self.redo: int | None = None
        self.solves = 0

    @property
    def adaptive(self) -> bool:
        return len(self.levels) > 1

    def _drive(self, k: int, n_sub: int) -> tuple[np.ndarray, ...]:
        """The times (n_sub,) s of the substeps from frame k - 1 to frame k, the prescribed
        d, v, a (n_sub, n_c) and applied forces (n_sub, n_free) or None at them (read-only:
        the same arrays are handed out again)."""
        if self._last_drive is not None and self._last_drive[0] == (k, n_sub):
            return self._last_drive[1]
        h = self.bc.frame_dt / n_sub
        times = (k - 1) * self.bc.frame_dt + h * np.arange(1, n_sub + 1)
        dd, vv, aa = self.bc.prescribed(times)
        drive = times, dd, vv, aa, None if self.force is None else self.force.free(times)
        self._last_drive = ((k, n_sub), drive)
        return drive

    def advance(
        self,
        state: State,
        k: int,
        n_sub: int,
        heat_too: bool = True,
        first: np.ndarray | None = None,
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """Steps from frame k - 1 to frame k in n_sub substeps (``first``: the first one's
        solve, already made); returns the dissipation, J (0 unless ``heat_too``), and the
        free DOFs' accelerations (n_free,) before the first and before the last substep."""
        integ = self.integrators.get(n_sub)
        times, dd, vv, aa, ff = self._drive(k, n_sub)
        heat, a_start = 0.0, state.a[integ.free]
        a_last = a_start
        for j in range(n_sub):
            d_old = state.d.copy()
            if j == n_sub - 1 and j > 0:
                a_last = state.a[integ.free]
            if j == 0 and first is not None:
                integ.finish_step(state, first, dd[j], vv[j], aa[j])
            else:
                integ.step(state, dd[j], vv[j], aa[j], None if ff is None else ff[j])
            if not np.isfinite(state.d).all():
                node = int(np.abs(d_old).reshape(-1, 3).max(axis=1).argmax())
                raise SimulationDiverged(
                    f"frame {k}, substep {j + 1} of {n_sub} (t = {times[j]:.6g} s): "
                    f"displacement became NaN/Inf; largest displacement before it "
                    f"{np.abs(d_old).max():.3e} m at node {node}; reduce params.dt or "
                    "check materials"
                )
            if heat_too:
                heat += integ.dissipation(state.d - d_old)
        return heat, a_start, a_last

    def frame(self, state: State, k: int) -> float:
        """Advance ``state`` to frame k; returns the viscous dissipation of the step, J
        (meaningless when ``redo`` is set)."""
        self.redo, self.solves = None, self.levels[0]
        if not self.adaptive:
            self.substeps[k] = self.levels[0]
            return self.advance(state, k, self.levels[0])[0]
        doubling = self.estimate == "doubling"
        if self.level == 0 and not doubling:
            return self._waited(state, k)
        saved = (state.d.copy(), state.v.copy(), state.a.copy())
        last = len(self.levels) - (2 if doubling else 1)
        checks = self.check_steps
        while True:
            heat, error, n_sub, discarded = (
                self._doubled(state, k, saved) if doubling else self._estimated(state, k)
            )
            if error <= self.tol or self.level == last:
                self.over += error > self.tol
                break
            state.d[:], state.v[:], state.a[:] = saved
            self.check_steps += discarded + n_sub
            self.level += 1
        # the frame's error ~ h^2: next frame one level coarser when it would stay in tol / 2
        if self.level > 0:
            coarser = n_sub * self.levels[self.level - 1] // self.levels[self.level]
            if error * (n_sub / coarser) ** 2 < self.tol / 2:
                self.level -= 1
        self.substeps[k] = n_sub
        self.check_steps += discarded
        self._a_before = self._a_last
        # the frame's own steps and estimates, less a first substep solved with the last one
        self.solves = n_sub + self.check_steps - checks + 1
        return heat

    def _stepped(self, state: State, k: int, n_sub: int) -> tuple[float, np.ndarray]:
        """The frame in n_sub substeps (the first one's solve taken from ``_ahead`` when
        made for it) and the right-hand side (n_free,) of its Zienkiewicz-Xie estimate of
        its substeps' summed local errors: (heat J, right-hand side)."""
        ahead, self._ahead = self._ahead, None
        first = ahead[2] if ahead is not None and ahead[:2] == (k, n_sub) else None
        self.check_steps += ahead is not None and first is None  # solved, not used
        heat, a_start, a_last = self.advance(state, k, n_sub, first=first)
        integ, frame_dt = self.integrators.get(n_sub), self.bc.frame_dt
        defect = self.bc.drive_defect((k - 1) * frame_dt, frame_dt / n_sub, n_sub)
        before = a_start if self._a_before is None else self._a_before
        centred = 0.5 * ((state.a[integ.free] + a_last) - (a_start + before))
        self._a_last = a_last
        return heat, integ.local_error_rhs(centred, defect)

    def _solved_with_next(
        self, state: State, k: int, n_sub: int, rhs: list[np.ndarray]
    ) -> np.ndarray:
        """Solves the right-hand sides ``rhs`` (each (n_free,)) together with the next
        frame's first substep at n_sub substeps (kept in ``_ahead``): (n_free, len(rhs))."""
        integ = self.integrators.get(n_sub)
        if k + 1 < self.bc.n_frames:
            _, dd, vv, aa, ff = self._drive(k + 1, n_sub)
            rhs = [*rhs, integ.step_rhs(state, dd[0], vv[0], aa[0], None if ff is None else ff[0])]
        solved = integ.solve(np.column_stack(rhs))
        if k + 1 < self.bc.n_frames:
            self._ahead = (k + 1, n_sub, solved[:, -1])
            return solved[:, :-1]
        return solved

    def _estimated(self, state: State, k: int) -> tuple[float, float, int, int]:
        """The frame in the current level's substeps with its error estimate (one more
        solve): (heat J, error m, substeps, steps discarded)."""
        n_sub = self.levels[self.level]
        heat, rhs = self._stepped(state, k, n_sub)
        error = self._solved_with_next(state, k, n_sub, [rhs])
        return heat, float(np.abs(error).max()), n_sub, 0

    def _waited(self, state: State, k: int) -> float:
        """The frame at the coarsest step size, its estimate left waiting; the waiting
        estimates solved once ``_batch`` of them wait or at the last frame. Any over the
        tolerance rewinds the run to the first such frame, one level finer (``redo``)."""
        n_sub, a_before = self.levels[0], self._a_before
        before = (state.d.copy(), state.v.copy(), state.a.copy())
        fed = self._ahead is not None and self._ahead[:2] == (k, n_sub)
        heat, rhs = self._stepped(state, k, n_sub)
        self._waiting.append(_Waiting(k, before, a_before, rhs))
        self.substeps[k] = n_sub
        self._a_before = self._a_last
        self.solves = 0 if fed else n_sub
        if len(self._waiting) < self._batch and k + 1 < self.bc.n_frames:
            return heat
        batch, self._waiting = self._waiting, []
        self.solves = 0
        errors = np.abs(self._solved_with_next(state, k, n_sub, [w.rhs for w in batch]))
        over = np.flatnonzero(errors.max(axis=0) > self.tol)
        if over.size == 0:
            self._batch = min(2 * self._batch, ERROR_BATCH)
            return heat
        j = int(over[0])
        first = batch[j]
        state.d[:], state.v[:], state.a[:] = first.before
        self._a_before = first.a_before
        self.check_steps += n_sub * (len(batch) - j) + (self._ahead is not None)
        self._ahead = None
        self.level, self._batch, self.redo = 1, 1, first.k
        return heat

    def _doubled(
        self, state: State, k: int, saved: tuple[np.ndarray, ...]
    ) -> tuple[float, float, int, int]:
        """The frame in n and 2n substeps from the same state, the finer kept, with its
        Richardson estimate: (heat J, error m, substeps kept, steps discarded)."""
        coarse, fine = self.levels[self.level], self.levels[self.level + 1]
        self.advance(state, k, coarse, heat_too=False)
        d_coarse = state.d.copy()
        state.d[:], state.v[:], state.a[:] = saved
        heat = self.advance(state, k, fine)[0]
        error = float(np.abs(state.d - d_coarse).max()) / ((fine / coarse) ** 2 - 1)
        return heat, error, fine, coarse
