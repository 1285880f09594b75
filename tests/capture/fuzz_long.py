"""The long form of the input fuzzing (issue #35): ``python -m tests.capture.fuzz_long
[--capture N] [--configs N]``. Damages N capture files of each kind (default 60: 360 files)
and generates N configs per config test (default 1000: --set values, -c files and raw --set
text 1000 each, sweep files N/4), then prints the figures as a Markdown table (docs/FUZZING.md).
Exits 1 on any defect (a traceback, an unnamed refusal or a silently wrong result)."""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path


def mutation_class(mutation: str) -> str:
    """A mutation's kind without its numbers: 'truncate', 're-encoded: resize', 'scaled'..."""
    text = mutation.split(" (")[0]
    if text.startswith("set to "):
        return "wrong type (" + text.removeprefix("set to ") + ")"
    if text.endswith(" swapped"):
        return "two fields swapped"
    return text


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--capture", type=int, default=60, help="damaged files per kind")
    parser.add_argument("--configs", type=int, default=1000, help="examples per config test")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    os.environ["PHYSANIM_FUZZ_EXAMPLES"] = str(args.configs)
    from tests.capture.fuzz import KINDS, Pristine, judge
    from tests.foundation import test_fuzz_configs as cfg

    rows: list[tuple[str, int, int, int, int]] = []
    by_mutation: Counter[tuple[str, str]] = Counter()
    defects = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        pristine = Pristine.make(Path(tmp) / "demo", n_frames=3)
        for kind in KINDS:
            counts: Counter[str] = Counter()
            for i in range(args.capture):
                outcome = judge(pristine, kind, random.Random(f"{args.seed}-{kind}-{i}"),
                                Path(tmp) / "work")  # fmt: skip
                counts[outcome.verdict] += 1
                by_mutation[(mutation_class(outcome.damage.mutation), outcome.verdict)] += 1
                if outcome.defect:
                    defects.append(outcome.line())
            n_bad = counts["traceback"] + counts["unnamed"] + counts["wrong"]
            rows.append((kind, args.capture, counts["accepted"], counts["refused"], n_bad))
    t_capture = time.perf_counter() - t0
    t0 = time.perf_counter()
    for test in (cfg.test_set_overrides, cfg.test_config_files, cfg.test_raw_set_text,
                 cfg.test_sweep_files):  # fmt: skip
        try:
            test()
        except Exception as exc:  # a defect: Hypothesis re-raises the (shrunk) failure
            defects.append(f"{test.__name__}: {exc}")
    for name in sorted({k for k, _ in cfg.STATS}):
        acc, ref = cfg.STATS[(name, "accepted")], cfg.STATS[(name, "refused")]
        rows.append((name, acc + ref, acc, ref, 0))
    t_configs = time.perf_counter() - t0
    print(
        "| input | generated | accepted (= undamaged result) | refused, naming file and "
        "field | defects |"
    )
    print("|---|---:|---:|---:|---:|")
    for kind, n, acc, ref, bad in rows:
        print(f"| {kind} | {n} | {acc} | {ref} | {bad} |")
    print("\n| capture mutation | accepted | refused | defects |\n|---|---:|---:|---:|")
    for name in sorted({m for m, _ in by_mutation}):
        bad = sum(by_mutation[(name, v)] for v in ("traceback", "unnamed", "wrong"))
        acc, ref = by_mutation[(name, "accepted")], by_mutation[(name, "refused")]
        print(f"| {name} | {acc} | {ref} | {bad} |")
    print(f"\ncapture: {t_capture:.0f} s, configs: {t_configs:.0f} s; defects: {len(defects)}")
    for line in defects:
        print("DEFECT", line)
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
