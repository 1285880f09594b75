"""Per-frame monitors of an FEM run: energy (and blow-up), elastic stress, inverted tets.

Each monitor is called once per output frame with the frame's state and element
displacements, and holds its (T,) series for :class:`physanim.fem.simulate.SimResult`. A run
rewound to an earlier frame (``FrameStepper.redo``) records the frames from it again: what a
monitor holds for frame k depends only on frames 0..k as last recorded.
"""

from __future__ import annotations

import numpy as np

from physanim.fem.geometry import signed_volumes
from physanim.fem.kinematics import Kinematics
from physanim.fem.model import FemModel
from physanim.fem.newmark import State
from physanim.fem.parallel_spmv import SymmetricQuadraticForm
from physanim.fem.stepping import SimulationDiverged


class EnergyMonitor:
    """kinetic, strain (T,) J; dissipated (T,) J cumulative viscous dissipation since frame 0.
    ``check`` stops a run whose mechanical energy exceeds ``blowup_factor`` times the larger
    of its past maximum and the drive's energy scale ``drive_energy`` (J)."""

    def __init__(
        self,
        model: FemModel,
        kin: Kinematics,
        n_frames: int,
        drive_energy: float,
        blowup_factor: float,
    ) -> None:
        self._kinetic_form = SymmetricQuadraticForm(model.M)
        self._kin = kin
        self.kinetic, self.strain, self.dissipated = (np.zeros(n_frames) for _ in range(3))
        self.drive_energy, self.blowup_factor = drive_energy, blowup_factor

    def record(self, k: int, state: State, u_elem: np.ndarray) -> None:
        self.kinetic[k] = 0.5 * self._kinetic_form(state.v)
        self.strain[k] = self._kin.strain_energy(state.d, u_elem)

    def check(self, k: int, heat: float, frame_dt: float, displacements: np.ndarray) -> None:
        """After frame k is recorded: add its dissipation ``heat`` (J), raise
        SimulationDiverged on an energy blow-up (message names the largest of
        ``displacements`` (N, 3) m)."""
        energy = self.kinetic[k] + self.strain[k]
        if k == 0:
            return
        self.dissipated[k] = self.dissipated[k - 1] + heat
        scale = max((self.kinetic[:k] + self.strain[:k]).max(), self.drive_energy)
        if energy > self.blowup_factor * scale and energy > 0:
            node = int(np.linalg.norm(displacements, axis=1).argmax())
            raise SimulationDiverged(
                f"frame {k} (t = {k * frame_dt:.6g} s): energy "
                f"{energy:.3e} J exceeds {self.blowup_factor:g} x "
                f"{scale:.3e} J; largest displacement "
                f"{np.linalg.norm(displacements, axis=1).max():.3e} m at node {node}"
            )


class StressMonitor:
    """Elastic von Mises stress: its peak ``max`` and 99th percentile ``p99`` (T,) Pa."""

    def __init__(self, model: FemModel, n_frames: int) -> None:
        self.model = model
        self.max, self.p99 = np.zeros(n_frames), np.zeros(n_frames)

    def record(self, k: int, state: State, u_elem: np.ndarray) -> None:
        stress = self.model.von_mises(u_elem)
        self.max[k], self.p99[k] = stress.max(), np.percentile(stress, 99)


class InversionMonitor:
    """``count`` (T,) inverted tets per frame; ``tets()`` ids inverted in any frame."""

    def __init__(self, model: FemModel, n_frames: int) -> None:
        self.model = model
        self.count = np.zeros(n_frames, dtype=np.int64)
        self._inverted: dict[int, np.ndarray] = {}  # frame -> its inverted tets, where any

    def record(self, k: int, state: State, u_elem: np.ndarray) -> None:
        m = self.model
        bad = np.flatnonzero(signed_volumes(m.nodes + state.d.reshape(-1, 3), m.tets) <= 0)
        self.count[k] = bad.size
        self._inverted.pop(k, None)
        if bad.size:
            self._inverted[k] = bad

    def tets(self) -> np.ndarray:
        return np.unique(np.concatenate([np.zeros(0, np.int64), *self._inverted.values()]))
