"""Fault-injection campaign over the store: seeded random faults, each followed by the checks
that nothing was lost, nothing partial was left and the outputs equal an undisturbed run's.

    .venv/bin/python -m tests.reliability.campaign --faults 200 --seed 1 --face 12 \\
        --json campaign.json

prints a table of the faults injected by kind and their outcomes, and writes the summary and
every fault's record as JSON.  ``tests/reliability/test_campaign.py`` runs a short form.

Faults (``KINDS``), on the toy DAG (``tests.foundation.toy_stages:TOY``, deterministic) and,
with ``--face N``, on the coarse face DAG:

- ``kill9``: the run SIGKILLs itself at a random write or rename under the store (injector
  ``kill:N``: inside a chunk write, a commit, a run manifest); ``kill9_timer``: SIGKILL from
  outside, a random moment after the first temporary output appears;
- ``enospc`` / ``eio``: the N-th write under the store fails after half its data (ENOSPC: and
  every later one, the disk stays full); ``rename_eio``: the N-th rename fails with EIO;
  ``efbig``: a random RLIMIT_FSIZE (writes beyond it fail with EFBIG, from the kernel);
- ``chunk_delete``, ``chunk_corrupt`` (one bit flipped), ``chunk_truncate``: a random file of
  a complete output; ``meta_truncate``: a ``zarr.json`` (the output's, an array's, a stage
  group's or the store's) cut short; ``meta_bitflip``: one bit of an output's ``zarr.json``;
- ``concurrent``: two to four runs of random configs (some forced, one sometimes killed) at
  once on one store.

After each fault: the failed run said one ``error:`` line (no traceback) and left nothing in
``.tmp/``; ``physanim verify`` passes, or names the damaged output (stage, key, file) and so
does ``status``; a re-run (``--verify`` after damage) completes; the config's outputs equal
the undisturbed reference byte for byte (its ``zarr.json`` without the run's times and host);
every output intact before the fault still is; and the store holds nothing partial: ``.tmp/``
empty, no stray temporary file, every group at a final path intact with exactly the files of
its manifest.  The face DAG's ``scan`` and ``tetra`` differ run to run, so its faults force or
damage only the other stages, and its outputs are compared with those before the fault.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import json
import math
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from physanim.store import StageStore
from physanim.store.stage_store import QUARANTINE, RUNS, TMP
from tests.commands import ROOT, TOY, invoke, physanim_env
from tests.reliability.injector import inject

WRITE_KINDS = ("kill9", "kill9_timer", "enospc", "eio", "rename_eio", "efbig")
DAMAGE_KINDS = (
    "chunk_delete",
    "chunk_corrupt",
    "chunk_truncate",
    "meta_truncate",
    "meta_bitflip",
)
KINDS = (*WRITE_KINDS, *DAMAGE_KINDS, "concurrent")
FACE_KINDS = ("kill9", "enospc", "eio", "chunk_delete", "chunk_corrupt", "meta_truncate")

#: Toy configs (``--set`` values); the last has arrays of several chunks written concurrently
TOY_VARIANTS: tuple[tuple[str, ...], ...] = (
    (),
    ("scale.factor=3.0",),
    ("source.n_frames=40",),
    ("source.n_frames=40", "scale.factor=0.5"),
    ("source.n_frames=1100", "scale.factor=1.5"),
)
TOY_STAGES = ("source", "scale", "total")
#: Face stages whose output is the same every run (``scan`` and ``tetra`` are not, and
#: ``simulate``'s last bits follow the solver's thread count, which differs between processes)
FACE_DETERMINISTIC = (
    "ingest",
    "track",
    "fit",
    "align",
    "tiles",
    "materials",
    "evaluate",
    "render",
)
#: Face stages a fault forces or damages (recomputed with the same key; ``simulate`` compared
#: by key only)
FACE_TARGETS = (*FACE_DETERMINISTIC, "simulate")
COARSE = "tests/face_pipeline/coarse.yaml"
#: Attributes of an output's zarr.json that differ between two runs of the same computation
VOLATILE = {"started", "finished", "duration_s", "host", "metadata_sha256"}
#: ... and the timings among its summary's figures (render_s_per_frame...)
TIMING = re.compile(r"(_s|_s_per_\w+|seconds)$")
STRAY = re.compile(r"(\.partial$|^\.[^.]+\.[0-9a-f]{32}$)")  # Zarr's and write_atomic's temps


@dataclasses.dataclass
class Record:
    """One injected fault and what was seen after it."""

    index: int
    dag: str
    kind: str
    detail: str = ""
    fired: bool = False  # the fault happened (the run was killed or failed, damage was made)
    run_rc: int | None = None
    error_line: str = ""
    named_by_verify: bool | None = None
    named_by_status: bool | None = None
    leftovers: list[str] = dataclasses.field(default_factory=list)  # .tmp/ after a failed run
    removed_by_verify: int = 0
    quarantined: int = 0
    problems: list[str] = dataclasses.field(default_factory=list)
    seconds: float = 0.0

    @property
    def outcome(self) -> str:
        if self.problems:
            return "FAILED"
        if not self.fired:
            return "not fired, passed"
        if self.kind in DAMAGE_KINDS:
            return "detected, recomputed"
        if self.kind == "concurrent":
            return "passed"
        return "killed, recovered" if self.run_rc == -9 else "failed cleanly, recovered"


def _digest(path: Path) -> str:
    if path.name == "zarr.json":
        document = json.loads(path.read_text())
        attrs = document.get("attributes", {})
        if "complete" in attrs:  # an output's own metadata: without the run's times and host
            attrs = {k: v for k, v in attrs.items() if k not in VOLATILE}
            if isinstance(attrs.get("summary"), dict):
                attrs["summary"] = {
                    k: v for k, v in attrs["summary"].items() if not TIMING.search(k)
                }
            document["attributes"] = attrs
        return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


def output_digest(store: StageStore, stage: str, key: str) -> dict[str, str]:
    """Relative path -> SHA-256 of every file of one output (zarr.json normalised)."""
    root = store.root / stage / key
    return {
        p.relative_to(root).as_posix(): _digest(p) for p in sorted(root.rglob("*")) if p.is_file()
    }


def layout_problems(store: StageStore) -> list[str]:
    """Anything partial, stray or damaged in the store (``.quarantine/`` aside)."""
    found = []
    root = store.root
    tmp = root / TMP
    if tmp.is_dir() and any(tmp.iterdir()):
        found.append(f".tmp/ holds {sorted(p.name for p in tmp.iterdir())}")
    for p in root.rglob("*"):
        rel = p.relative_to(root)
        if rel.parts[0] == QUARANTINE:
            continue
        if STRAY.search(p.name):
            found.append(f"stray temporary file {rel}")
    for p in root.iterdir():
        if p.name not in ("zarr.json", "LATEST", RUNS, TMP, QUARANTINE) and not p.is_dir():
            found.append(f"unexpected file {p.name}")
    for p in (root / RUNS).iterdir() if (root / RUNS).is_dir() else []:
        try:
            json.loads(p.read_text())["keys"]
        except (OSError, ValueError, KeyError, TypeError):
            found.append(f"unreadable run manifest {p.name}")
    for stage in store.stages():
        try:
            json.loads((root / stage / "zarr.json").read_text())
        except ValueError:
            found.append(f"unreadable stage group metadata {stage}/zarr.json")
        for key in store.all_keys(stage):
            problem = store.damage(stage, key, checksums=True)
            if problem is not None:
                found.append(f"{stage}/{key[:12]} at its final path is damaged: {problem}")
                continue
            manifest = store.provenance(stage, key).get("manifest") or {}
            group = root / stage / key
            files = {q.relative_to(group).as_posix() for q in group.rglob("*") if q.is_file()}
            extra = files - set(manifest) - {"zarr.json"}
            if extra:
                found.append(f"{stage}/{key[:12]} holds files outside its manifest: {extra}")
    with contextlib.suppress(ValueError):
        json.loads((root / "zarr.json").read_text())
        return found
    return [*found, "unreadable store metadata zarr.json"]


def intact(store: StageStore) -> set[tuple[str, str]]:
    return {(s, k) for s in store.stages() for k in store.all_keys(s) if store.has(s, k)}


def _one_error_line(stderr: str) -> tuple[str, str | None]:
    """(the error line, a problem or None): exactly one ``error:`` line, no traceback."""
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    if "Traceback" in stderr:
        return "", "traceback: " + stderr[-600:]
    if len(errors) != 1:
        return "", f"{len(errors)} error lines: {stderr[-600:]}"
    return errors[0], None


def _names(text: str, stage: str, key: str, rel: str, path: Path) -> bool:
    """Whether a ``damaged:`` line of ``text`` names this output and file."""
    for line in text.splitlines():
        if not line.startswith(f"damaged: {stage}/{key[:12]}"):
            continue
        if str(path) in line or f"metadata {rel}" in line or f"file {rel}" in line:
            return True
        head, _, tail = rel.partition("/c/")
        if tail and f"array '{head}' chunk c/{tail}" in line:
            return True
    return False


class Dag:
    """One DAG under test: its store, its configs, and the reference outputs to compare with."""

    name: str
    stages: tuple[str, ...]
    variants: tuple[tuple[str, ...], ...]

    def __init__(self, work: Path) -> None:
        self.work = work
        work.mkdir(parents=True)
        self.dataset = work / "store"
        self.reference: dict[int, dict[str, tuple[str, dict[str, str]]]] = {}
        #: writes and renames under the store of a run of each variant on a fresh store, by
        #: stage ("": the rest)
        self.counts: dict[int, dict[str, list[int]]] = {}

    @property
    def store(self) -> StageStore:
        return StageStore(self.dataset / "runs" / "store.zarr", create=False)

    def args(self, variant: int, dataset: Path | None = None) -> list[str]:
        raise NotImplementedError

    def run_args(self, variant: int, dataset: Path | None = None) -> list[str]:
        return ["run", *self.args(variant, dataset), "--local"]

    def snapshot(self, store: StageStore, variant: int) -> dict[str, tuple[str, dict[str, str]]]:
        """Stage -> (key, output digest) of a variant's latest complete run in ``store``."""
        entries = self.plan(variant)
        return {s: (k, output_digest(store, s, k)) for s, k in entries.items()}

    def plan(self, variant: int) -> dict[str, str]:
        out = invoke("status", *self.args(variant), "--json")
        if out.returncode != 0:
            raise RuntimeError(out.stderr)
        return {row["stage"]: row["key"] for row in json.loads(out.stdout)}

    def deterministic(self, stage: str) -> bool:
        return True


class ToyDag(Dag):
    name = "toy"
    stages = TOY_STAGES
    variants = TOY_VARIANTS

    def __init__(self, work: Path) -> None:
        super().__init__(work)
        self.config = work / "toy.yaml"
        self.config.write_text(f"dataset:\n  name: toy\n  dir: {self.dataset}\n")

    def args(self, variant: int, dataset: Path | None = None) -> list[str]:
        sets = [a for s in self.variants[variant] for a in ("--set", s)]
        return ["-p", TOY, "-c", str(self.config), "--dataset", str(dataset or self.dataset), *sets]

    def prepare(self, log: Any) -> None:
        """Run every variant undisturbed, each in a fresh store (counting its writes and
        renames) and all in one reference store; keep what each produced."""
        ref = self.work / "reference"
        for v in range(len(self.variants)):
            fresh = self.work / f"count-{v}"
            with inject("count", 0, fresh / "runs" / "store.zarr") as seen:
                invoke(*self.run_args(v, fresh))
            self.counts[v] = seen.by_stage
            shutil.rmtree(fresh)
            out = invoke(*self.run_args(v, ref))
            if out.returncode != 0:
                raise RuntimeError(out.stderr)
        store = StageStore(ref / "runs" / "store.zarr", create=False)
        for v in range(len(self.variants)):
            keys = self._keys(v, ref)
            self.reference[v] = {s: (k, output_digest(store, s, k)) for s, k in keys.items()}
        log(f"toy: reference outputs of {len(self.variants)} configs")

    def _keys(self, variant: int, dataset: Path) -> dict[str, str]:
        out = invoke("status", *self.args(variant, dataset), "--json")
        return {row["stage"]: row["key"] for row in json.loads(out.stdout)}

    def plan(self, variant: int) -> dict[str, str]:
        return self._keys(variant, self.dataset)


class FaceDag(Dag):
    """The coarse face DAG: one config; compared with the outputs before each fault."""

    name = "face"
    variants = ((),)

    def __init__(self, work: Path) -> None:
        super().__init__(work)
        self.stages = FACE_TARGETS
        self.dataset = work / "demo"  # a dataset named demo is generated by the first run

    def args(self, variant: int, dataset: Path | None = None) -> list[str]:
        return ["--dataset", str(dataset or self.dataset), "-c", COARSE]

    def prepare(self, log: Any) -> None:
        t0 = time.perf_counter()
        with inject("count", 0, self.dataset / "runs" / "store.zarr") as seen:
            out = invoke(*self.run_args(0))
        self.counts[0] = seen.by_stage
        if out.returncode != 0:
            raise RuntimeError(out.stderr[-3000:])
        self.reference[0] = self.snapshot(self.store, 0)
        log(f"face: coarse demo made and run in {time.perf_counter() - t0:.0f} s")

    def deterministic(self, stage: str) -> bool:
        return stage in FACE_DETERMINISTIC


class Campaign:
    def __init__(self, work: Path, seed: int, verbose: bool = True) -> None:
        self.work, self.rng, self.verbose = work, random.Random(seed), verbose
        self.records: list[Record] = []

    def log(self, text: str) -> None:
        if self.verbose:
            print(text, flush=True)

    # -- commands ------------------------------------------------------------------------
    def child(
        self, args: list[str], inject: str | None = None, root: Path | None = None, **popen: Any
    ) -> subprocess.Popen[str]:
        """``physanim ARGS`` in a child process through the injector."""
        env = physanim_env()
        if inject:
            report = self.work / "injector-report.json"
            report.unlink(missing_ok=True)
            env |= {
                "PHYSANIM_INJECT": inject,
                "PHYSANIM_INJECT_ROOT": str(root),
                "PHYSANIM_INJECT_REPORT": str(report),
            }
        return subprocess.Popen(
            [sys.executable, "-m", "tests.reliability.injector", *args],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            **popen,
        )

    def cli(self, *args: str) -> subprocess.CompletedProcess[str]:
        """``physanim ARGS`` in this process; a traceback becomes rc 99 with the exception."""
        try:
            return invoke(*args)
        except Exception as exc:  # noqa: BLE001 - any escape is a finding
            return subprocess.CompletedProcess(list(args), 99, "", f"Traceback: {exc!r}")

    # -- the checks after a fault --------------------------------------------------------
    def settle(
        self,
        dag: Dag,
        rec: Record,
        variants: list[int],
        before: set[tuple[str, str]],
        damaged: tuple[str, str, str, Path] | None = None,
        touched: set[str] | frozenset[str] = frozenset(),
        group_meta: Path | None = None,
    ) -> None:
        """status, verify, re-run, compare, and look for anything partial (``damaged``: the
        output and file a damage fault hit, ``group_meta``: the store's or a stage's group
        metadata it cut; ``touched``: the stages the fault may have recomputed, compared by
        key only when not deterministic)."""
        store = dag.store
        flags = ("--verify",) if rec.kind in ("chunk_corrupt", "meta_bitflip") else ()
        status = self.cli("status", *dag.args(variants[0]), *flags)
        verify = self.cli("verify", *dag.args(variants[0]))
        rec.removed_by_verify = verify.stdout.count("removed abandoned partial output")
        if damaged is not None:
            stage, key, rel, path = damaged
            rec.named_by_status = _names(status.stdout, stage, key, rel, path)
            rec.named_by_verify = verify.returncode == 1 and _names(
                verify.stdout, stage, key, rel, path
            )
            if not rec.named_by_verify:
                rec.problems.append(f"verify did not name {stage}/{rel}: {verify.stdout[-800:]}")
            if not rec.named_by_status:
                rec.problems.append(f"status did not name {stage}/{rel}: {status.stdout[-1500:]}")
        elif verify.returncode != 0:
            rec.problems.append(f"verify rc={verify.returncode}: {verify.stdout[-800:]}")
        if group_meta is not None:  # verify rewrites it (an empty group), saying so
            rec.named_by_status = f"damaged: group metadata {group_meta} " in status.stdout
            rec.named_by_verify = f"rewrote unreadable group metadata {group_meta}" in verify.stdout
            if not rec.named_by_status or not rec.named_by_verify:
                rec.problems.append(
                    f"{group_meta} not named: {status.stdout[-300:]}, {verify.stdout}"
                )
        tmp = store.root / TMP
        if tmp.is_dir() and any(tmp.iterdir()):
            rec.problems.append(f".tmp/ not empty after verify: {os.listdir(tmp)}")
        for v in dict.fromkeys(variants):
            again = self.cli(*dag.run_args(v), *(("--verify",) if damaged else ()))
            said = (again.stdout + again.stderr).splitlines()
            recomputed = {line.split(":")[0] for line in said if ": ran in " in line}
            rec.quarantined += (again.stdout + again.stderr).count(" is damaged")
            if again.returncode != 0:
                rec.problems.append(f"re-run rc={again.returncode}: {again.stderr[-800:]}")
                continue
            got = dag.snapshot(store, v)
            for stage, (key, files) in dag.reference[v].items():
                if stage in recomputed | touched and not dag.deterministic(stage):
                    files = got.get(stage, ("", {}))[1]  # its key only
                if got.get(stage, ("", {}))[0] != key:
                    rec.problems.append(f"{stage}: key {got.get(stage)} != reference {key[:12]}")
                elif got[stage][1] != files:
                    diff = sorted(
                        f
                        for f in set(files) | set(got[stage][1])
                        if files.get(f) != got[stage][1].get(f)
                    )
                    rec.problems.append(
                        f"{stage}/{key[:12]} differs from the reference: {diff[:5]}"
                    )
            if isinstance(dag, FaceDag):  # the next fault compares with what is there now
                dag.reference[v] = got
        lost = {o for o in before if not store.has(*o)}
        if lost:
            rec.problems.append(f"outputs lost: {sorted(lost)}")
        rec.problems += layout_problems(store)
        final = self.cli("verify", *dag.args(variants[0]))
        if final.returncode != 0 or "0 damaged" not in final.stdout:
            rec.problems.append(f"final verify: {final.stdout[-500:]}")

    # -- faults --------------------------------------------------------------------------
    def write_fault(self, dag: Dag, rec: Record) -> None:
        rng, kind = self.rng, rec.kind
        v = rng.randrange(len(dag.variants))
        if dag.name == "toy" and rng.random() < 0.25:
            shutil.rmtree(dag.dataset, ignore_errors=True)  # a fresh store: every stage writes
        store = dag.store
        if not (store.root / "zarr.json").exists() and dag.name == "face":
            raise RuntimeError("the face store is gone")
        keys = dag.plan(v) if (store.root / "zarr.json").exists() else {}
        present = {s for s, k in keys.items() if store.has(s, k)}
        extra: list[str] = []
        if dag.name == "face":  # one deterministic stage, alone
            stage = rng.choice(dag.stages)
            extra = ["--only", stage, "--force", stage]
            written = {stage}
        else:
            forced = rng.sample(TOY_STAGES, rng.randint(1, 3)) if present else []
            extra = [a for s in forced for a in ("--force", s)]
            first = min((TOY_STAGES.index(s) for s in forced), default=len(TOY_STAGES))
            written = {s for i, s in enumerate(TOY_STAGES) if i >= first or s not in present}
        before = intact(store) if (store.root / "zarr.json").exists() else set()
        # the writes and renames this run makes, about (as counted in an undisturbed run)
        counted = [n for s, n in dag.counts[v].items() if s in written or s == ""]
        writes, renames = (max(1, sum(n[i] for n in counted)) for i in (0, 1))
        args = [*dag.run_args(v), *extra]
        root = dag.dataset / "runs" / "store.zarr"
        rec.detail = " ".join([*dag.variants[v], *extra]) or "default config"
        if kind == "kill9_timer":
            proc = self.child(args)
            deadline = time.time() + 120
            while proc.poll() is None and time.time() < deadline:
                if (root / TMP).is_dir() and any((root / TMP).iterdir()):
                    time.sleep(rng.uniform(0.0, 0.15))
                    proc.kill()
                    break
                time.sleep(0.005)
        elif kind == "efbig":
            limit = round(math.exp(rng.uniform(math.log(64), math.log(50_000))))
            rec.detail += f"; RLIMIT_FSIZE {limit} B"

            def preexec(limit: int = limit) -> None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
                signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

            proc = self.child(args, preexec_fn=preexec)
        else:
            inject, n = {
                "kill9": ("kill", rng.randint(1, writes + renames)),
                "enospc": ("enospc", rng.randint(1, writes)),
                "eio": ("eio", rng.randint(1, writes)),
                "rename_eio": ("rename", rng.randint(1, renames)),
            }[kind]
            rec.detail += f"; {inject}:{n} (~{writes} writes, ~{renames} renames)"
            proc = self.child(args, f"{inject}:{n}", root)
        out, err = proc.communicate(timeout=600)
        rec.run_rc = proc.returncode
        rec.fired = proc.returncode != 0
        report = self.work / "injector-report.json"
        if proc.returncode not in (0, -9) and kind not in ("efbig", "kill9_timer"):
            seen = json.loads(report.read_text()) if report.exists() else {}
            if not seen.get("fired"):  # the run failed, but not of the fault
                rec.problems.append(f"the run failed before its fault: {err[-600:]}")
        if proc.returncode == -9:
            pass
        elif proc.returncode != 0:
            rec.error_line, problem = _one_error_line(err)
            if problem:
                rec.problems.append(problem)
            tmp = root / TMP
            rec.leftovers = sorted(os.listdir(tmp)) if tmp.is_dir() else []
            if rec.leftovers:
                rec.problems.append(f"the failed run left {rec.leftovers} in .tmp/")
        self.settle(dag, rec, [v], before, touched=written)

    def damage_fault(self, dag: Dag, rec: Record) -> None:
        rng, kind = self.rng, rec.kind
        v = rng.randrange(len(dag.variants))
        first = self.cli(*dag.run_args(v))
        if first.returncode != 0:
            rec.problems.append(f"undisturbed run failed: {first.stderr[-500:]}")
            return
        store = dag.store
        keys = dag.plan(v)
        stage = rng.choice(dag.stages)
        key = keys[stage]
        group = store.root / stage / key
        manifest = store.provenance(stage, key)["manifest"]
        before = intact(store)
        if kind == "meta_truncate":
            arrays = [r for r in manifest if r.endswith("zarr.json")]
            pick = rng.random()
            if pick < 0.1:  # the stage group's or the store's: holds nothing of an output
                target = rng.choice([store.root / stage / "zarr.json", store.root / "zarr.json"])
            else:
                rel = "zarr.json" if pick < 0.7 or not arrays else rng.choice(arrays)
                target = group / rel
        elif kind == "meta_bitflip":
            target = group / "zarr.json"
        else:
            chunks = [r for r in manifest if not r.endswith("zarr.json")]
            target = group / rng.choice(chunks)
        rel = target.relative_to(group).as_posix() if group in target.parents else ""
        data = target.read_bytes()
        if kind == "chunk_delete":
            target.unlink()
        elif kind in ("chunk_corrupt", "meta_bitflip"):
            i = rng.randrange(len(data))
            bit = rng.randrange(8)
            target.write_bytes(data[:i] + bytes([data[i] ^ (1 << bit)]) + data[i + 1 :])
            rec.detail = f"bit {bit} of byte {i}"
        else:
            size = rng.randrange(len(data))
            target.write_bytes(data[:size])
            rec.detail = f"cut to {size} of {len(data)} bytes"
        where = target.relative_to(store.root).as_posix().replace(key, key[:12])
        rec.detail = f"{where} ({' '.join(dag.variants[v]) or 'default config'}): {rec.detail}"
        rec.fired = True
        if not rel:  # the store's or a stage's group: holds no output
            self.settle(dag, rec, [v], before, group_meta=target)
            return
        self.settle(dag, rec, [v], before - {(stage, key)}, damaged=(stage, key, rel, target))

    def concurrent_fault(self, dag: Dag, rec: Record) -> None:
        rng = self.rng
        n = rng.randint(2, 4)
        variants = [rng.randrange(len(dag.variants)) for _ in range(n)]
        store_exists = (dag.store.root / "zarr.json").exists()
        before = intact(dag.store) if store_exists else set()
        cmds = []
        for v in variants:
            extra = ["--force", rng.choice(TOY_STAGES)] if rng.random() < 0.3 else []
            cmds.append([*dag.run_args(v), *extra])
        victim = rng.randrange(n) if rng.random() < 0.3 else None
        procs = [self.child(c) for c in cmds]
        if victim is not None:
            time.sleep(rng.uniform(0.5, 2.5))
            procs[victim].kill()
        outs = [p.communicate(timeout=600) for p in procs]
        rec.detail = f"{n} runs: " + "; ".join(
            " ".join(c[c.index("--local") + 1 :] + list(dag.variants[v])) or "default"
            for c, v in zip(cmds, variants, strict=True)
        )
        if victim is not None:
            rec.detail += f"; run {victim + 1} killed"
        rec.fired = True
        for i, (p, (_, err)) in enumerate(zip(procs, outs, strict=True)):
            if i == victim and p.returncode == -9:
                continue
            if p.returncode != 0:
                rec.problems.append(f"concurrent run {i + 1} rc={p.returncode}: {err[-600:]}")
        self.settle(dag, rec, variants, before)

    def fault(self, dag: Dag, kind: str) -> Record:
        rec = Record(len(self.records) + 1, dag.name, kind)
        t0 = time.perf_counter()
        try:
            if kind in WRITE_KINDS:
                self.write_fault(dag, rec)
            elif kind in DAMAGE_KINDS:
                self.damage_fault(dag, rec)
            else:
                self.concurrent_fault(dag, rec)
        except Exception as exc:  # noqa: BLE001 - the campaign itself must report, not stop
            rec.problems.append(f"campaign error: {type(exc).__name__}: {exc}")
        rec.seconds = round(time.perf_counter() - t0, 2)
        self.records.append(rec)
        mark = "ok " if not rec.problems else "BAD"
        self.log(f"{mark} {rec.index:4d} {dag.name:4s} {kind:14s} {rec.outcome:26s} {rec.detail}")
        for p in rec.problems:
            self.log(f"      - {p}")
        return rec

    def run(self, toy_faults: int, face_faults: int) -> None:
        toy = ToyDag(self.work / "toy")
        if toy_faults:
            toy.prepare(self.log)
        # every kind at least once, then at random
        kinds = list(KINDS) * (toy_faults // len(KINDS))
        kinds += self.rng.sample(KINDS, toy_faults - len(kinds))
        self.rng.shuffle(kinds)
        for kind in kinds:
            self.fault(toy, kind)
        if face_faults:
            face = FaceDag(self.work / "face")
            face.prepare(self.log)
            face_kinds = list(FACE_KINDS) * (face_faults // len(FACE_KINDS) + 1)
            for kind in face_kinds[:face_faults]:
                self.fault(face, kind)


def summary(records: list[Record], seconds: float, command: str) -> dict[str, Any]:
    by_kind: dict[str, Counter[str]] = defaultdict(Counter)
    for r in records:
        by_kind[f"{r.dag}/{r.kind}"][r.outcome] += 1
    return {
        "command": command,
        "faults": len(records),
        "failed": sum(1 for r in records if r.problems),
        "seconds": round(seconds, 1),
        "by_kind": {k: dict(c) for k, c in sorted(by_kind.items())},
        "named_by_verify": sum(1 for r in records if r.named_by_verify),
        "named_by_status": sum(1 for r in records if r.named_by_status),
        "partial_outputs_removed_by_verify": sum(r.removed_by_verify for r in records),
        "damaged_outputs_quarantined": sum(r.quarantined for r in records),
        "records": [{**dataclasses.asdict(r), "outcome": r.outcome} for r in records],
    }


OUTCOMES = (
    "killed, recovered",
    "failed cleanly, recovered",
    "detected, recomputed",
    "passed",
    "not fired, passed",
    "FAILED",
)


def table(data: dict[str, Any]) -> str:
    """The figures as a Markdown table: faults by kind and outcome."""
    head = ["fault", "injected", *OUTCOMES]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    totals: Counter[str] = Counter()
    for kind, counts in data["by_kind"].items():
        n = sum(counts.values())
        totals.update(counts)
        lines.append(
            "| " + " | ".join([kind, str(n), *(str(counts.get(o, 0)) for o in OUTCOMES)]) + " |"
        )
    lines.append(
        "| "
        + " | ".join(
            ["**all**", f"**{data['faults']}**", *(f"**{totals.get(o, 0)}**" for o in OUTCOMES)]
        )
        + " |"
    )
    return "\n".join(lines)


@contextlib.contextmanager
def workdir(keep: Path | None) -> Iterator[Path]:
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=False)
        yield keep
        return
    with tempfile.TemporaryDirectory(prefix="physanim-campaign-") as d:
        yield Path(d)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--faults", type=int, default=200, help="faults on the toy DAG")
    parser.add_argument("--face", type=int, default=0, help="faults on the coarse face DAG")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", type=Path, help="write the summary and records here")
    parser.add_argument("--workdir", type=Path, help="keep the stores here (a new folder)")
    parser.add_argument("--quiet", action="store_true", help="no line per fault")
    ns = parser.parse_args(argv)
    command = "python -m tests.reliability.campaign " + " ".join(
        a for a in (argv if argv is not None else sys.argv[1:])
    )
    t0 = time.perf_counter()
    with workdir(ns.workdir) as work:
        campaign = Campaign(work, ns.seed, verbose=not ns.quiet)
        campaign.run(ns.faults, ns.face)
    data = summary(campaign.records, time.perf_counter() - t0, command)
    print(table(data))
    print(
        f"{data['faults']} faults in {data['seconds']:.0f} s, {data['failed']} failed; damage "
        f"named by verify {data['named_by_verify']}, by status {data['named_by_status']}; "
        f"partial outputs removed by verify {data['partial_outputs_removed_by_verify']}"
    )
    if ns.json:
        ns.json.write_text(json.dumps(data, indent=1) + "\n")
    return 1 if data["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
