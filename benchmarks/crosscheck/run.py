"""Cross-check twolevel's CommonRoad rule pack against CommonRoad's own monitor (crmonitor).

    python benchmarks/crosscheck/run.py [--build [--python PYTHON]] [--crmonitor-python PATH]
                                        [--cases A,B,...] [--json OUT.json] [--keep DIR]

Both monitors judge the same drives (``cases.py``): twolevel evaluates ``rules/commonroad`` on
the signals its world computes; crmonitor (in its own virtual environment, ``make crosscheck``)
evaluates R_G1–R_G4 on the same drives written as CommonRoad XML by commonroad-io
(``crmonitor_side.py``). Per case and rule it prints on how many steps the verdicts agree (the
sign of the robustness), on how many crmonitor's unscaled robustness equals twolevel's (within
1 mm or 1e-6), and the rank correlation of the two robustness series.

The scales differ: twolevel's robustness is in SI units (metres, m/s, m/s²) and never clipped;
crmonitor divides each predicate's value by a constant (longitudinal distance 200 m, lateral
distance 20 m, speed 69.44 m/s, acceleration 10.5 m/s², angle π) and clips it to [−1, 1] before
min/max combine them. So a rule decided by one predicate maps as
twolevel = crmonitor × constant (R_G3: × 69.44 m/s while within it), while a rule mixing
predicates of different units compares only in sign and in the order of its values over time
(the correlation); with scaling off crmonitor's values are in SI units and can equal twolevel's.

The crmonitor Python is ``--crmonitor-python``, else ``$TWOLEVEL_CRMONITOR_PYTHON``, else
``.crosscheck/venv/bin/python`` in the repository, which ``--build [--python PYTHON3.11]`` creates
from ``requirements/crosscheck.txt`` (exact versions; ~1.7 GB, a few minutes; rebuilt when that
file changes). Exit status 0 after a comparison, 3 when that environment is missing or broken (the
message says how to build it).

Speed: crmonitor's CPU time per drive (its world from the scenario, then each rule) beside
twolevel's (its signals from its world, then the pack); the ``dense`` drive (20 vehicles, 100
steps) is the figure of merit.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cases as cc  # noqa: E402

VENV = cc.ROOT / ".crosscheck" / "venv"
VENV_PYTHON = VENV / "bin" / "python"
REQUIREMENTS = cc.ROOT / "requirements" / "crosscheck.txt"
TORCH_INDEX = "https://download.pytorch.org/whl/cpu"
"""Where torch's CPU build comes from (an index given for torch alone: for every other package
pip would ask it too)."""
SIDE = Path(__file__).resolve().with_name("crmonitor_side.py")
MISSING = 3


def build_venv(python: str = "python3.11") -> tuple[Path | None, str]:
    """crmonitor's environment at ``VENV`` from ``REQUIREMENTS`` with the interpreter ``python``
    (3.10 or 3.11), unless it is there for the same requirements already. Its Python, or None and
    why not (the last lines of what failed)."""
    stamp = VENV / ".requirements-sha256"
    want = hashlib.sha256(REQUIREMENTS.read_bytes()).hexdigest()
    if stamp.exists() and stamp.read_text().strip() == want and crmonitor_python(str(VENV_PYTHON)):
        return VENV_PYTHON, "up to date"
    if shutil.which(python) is None:
        return None, f"{python} not found (crmonitor needs Python 3.10 or 3.11: --python PATH)"
    shutil.rmtree(VENV, ignore_errors=True)
    torch = next(line for line in REQUIREMENTS.read_text().splitlines() if line.startswith("torch=="))
    for cmd in ([python, "-m", "venv", str(VENV)],
                [str(VENV_PYTHON), "-m", "pip", "install", "--quiet", "--no-deps", "--index-url", TORCH_INDEX, torch],
                [str(VENV_PYTHON), "-m", "pip", "install", "--quiet", "-r", str(REQUIREMENTS)],
                [str(VENV_PYTHON), "-m", "pip", "check"]):
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            return None, f"{' '.join(cmd[:4])} failed:\n" + "\n".join((proc.stdout + proc.stderr).splitlines()[-15:])
    if crmonitor_python(str(VENV_PYTHON)) is None:
        return None, "built, but `import crmonitor, commonroad` fails in it"
    stamp.write_text(want + "\n")
    return VENV_PYTHON, "built"


def crmonitor_python(explicit: str | None = None) -> Path | None:
    """The crmonitor environment's Python, if it exists and imports crmonitor."""
    path = Path(explicit or os.environ.get("TWOLEVEL_CRMONITOR_PYTHON") or VENV_PYTHON)
    if not path.exists():
        return None
    probe = subprocess.run([str(path), "-c", "import crmonitor, commonroad"], capture_output=True, text=True)
    return path if probe.returncode == 0 else None


def run_crmonitor(python: Path, exported: dict[str, dict], work: Path) -> dict:
    """crmonitor's robustness of every exported case (``crmonitor_side.py`` in its environment)."""
    src, dst = work / "cases.json", work / "crmonitor.json"
    src.write_text(json.dumps({"cases": exported}), encoding="utf-8")
    proc = subprocess.run([str(python), str(SIDE), str(src), str(dst), "--xml-dir", str(work / "xml")],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"crmonitor_side.py failed:\n{proc.stderr[-4000:]}")
    return json.loads(dst.read_text(encoding="utf-8"))


def compare(names: list[str], python: Path, work: Path, T: int = 100) -> dict:
    """Both monitors on the cases ``names``; the agreement per case and rule."""
    sets = cc.rulesets()
    ours: dict[str, dict[str, np.ndarray]] = {}
    cpu: dict[str, float] = {}
    exported: dict[str, dict] = {}
    signals_cpu: dict[str, float] = {}
    for name in names:
        tracks = cc.case(name, T)
        w = cc.world(len(tracks) - 1)
        c0 = time.process_time()
        sig = cc.signals(w, tracks)
        signals_cpu[name] = time.process_time() - c0
        ours[name], cpu[name] = cc.robustness(sig, sets)
        exported[name] = cc.export(tracks, sig)
    theirs = run_crmonitor(python, exported, work)
    rows = []
    for name in names:
        for rule in cc.RULES:
            mine = ours[name][rule]
            cr = theirs["cases"][name]["rules"][rule]
            scaled, unscaled = np.asarray(cr["scaled"]), np.asarray(cr["unscaled"])
            agree, n = cc.sign_agreement(mine, scaled)
            m = min(len(mine), len(unscaled))
            same = int(np.sum(np.isclose(mine[:m], unscaled[:m], rtol=1e-6, atol=1e-3)))
            rows.append({"case": name, "rule": rule, "steps": n, "sign_agree": agree, "value_agree": same,
                         "spearman": cc.spearman(mine, scaled), "ours_min": float(np.min(mine[:n])),
                         "crmonitor_min": float(np.min(scaled[:n])),
                         "disagree_steps": [int(k) for k in np.flatnonzero((mine[:n] >= 0) != (scaled[:n] >= 0))]})
    speed = []
    for name in names:
        cr = theirs["cases"][name]
        rules_cpu = sum(cr["rules"][rule]["scaled_cpu_s"] for rule in cc.RULES)
        speed.append({"case": name, "vehicles": len(exported[name]["vehicles"]), "steps": T,
                      "ours_signals_s": signals_cpu[name], "ours_rules_s": cpu[name],
                      "crmonitor_world_s": cr["world_cpu_s"], "crmonitor_rules_s": rules_cpu})
    return {"rows": rows, "speed": speed, "crmonitor": theirs}


def _fmt(x: float) -> str:
    return "  n/a" if not np.isfinite(x) else f"{x:+.2f}"


def main(argv: list[str]) -> int:
    if "--build" in argv:
        built, why = build_venv(argv[argv.index("--python") + 1] if "--python" in argv else "python3.11")
        print(f"crmonitor's environment {VENV.relative_to(cc.ROOT)}: {why}", file=sys.stderr)
        if built is None:
            return MISSING
    explicit = argv[argv.index("--crmonitor-python") + 1] if "--crmonitor-python" in argv else None
    python = crmonitor_python(explicit)
    if python is None:
        print("crmonitor's environment is missing or broken: build it with `make crosscheck` "
              "(a separate virtual environment, ~1.6 GB; see benchmarks/crosscheck/run.py)", file=sys.stderr)
        return MISSING
    keep = Path(argv[argv.index("--keep") + 1]) if "--keep" in argv else None
    with tempfile.TemporaryDirectory() as tmp:
        work = keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        names = argv[argv.index("--cases") + 1].split(",") if "--cases" in argv else list(cc.CASES)
        res = compare(names, python, work)
    rows = res["rows"]
    print(f"{'case':<18} {'rule':<5} {'steps':>5} {'signs agree':>11} {'= unscaled':>10} {'rank corr':>9} "
          f"{'min ours':>9} {'min crmon':>9}")
    for r in rows:
        print(f"{r['case']:<18} {r['rule']:<5} {r['steps']:>5} {r['sign_agree']:>11} {r['value_agree']:>10} "
              f"{_fmt(r['spearman']):>9} {r['ours_min']:>9.3f} {r['crmonitor_min']:>9.4f}")
    agree, total = sum(r["sign_agree"] for r in rows), sum(r["steps"] for r in rows)
    print(f"signs agree on {agree} of {total} steps ({100.0 * agree / max(total, 1):.2f} %) over "
          f"{len(rows) // len(cc.RULES)} drives x {len(cc.RULES)} rules; crmonitor imports in "
          f"{res['crmonitor']['import_s']:.1f} s")
    print(f"\nCPU time [ms] per drive of {res['speed'][0]['steps']} steps, the rules {', '.join(cc.RULES)}: twolevel "
          "(signals from its world, then the pack) beside crmonitor (its world, then the rules)")
    print(f"{'case':<18} {'vehicles':>8} {'signals':>8} {'pack':>7} {'cr world':>9} {'cr rules':>9} "
          f"{'x rules':>8} {'x all':>7}")
    for r in res["speed"]:
        ours_all, theirs_all = r["ours_signals_s"] + r["ours_rules_s"], r["crmonitor_world_s"] + r["crmonitor_rules_s"]
        print(f"{r['case']:<18} {r['vehicles']:>8} {1e3 * r['ours_signals_s']:>8.1f} {1e3 * r['ours_rules_s']:>7.1f} "
              f"{1e3 * r['crmonitor_world_s']:>9.0f} {1e3 * r['crmonitor_rules_s']:>9.0f} "
              f"{r['crmonitor_rules_s'] / max(r['ours_rules_s'], 1e-9):>7.0f}x {theirs_all / max(ours_all, 1e-9):>6.0f}x")
    if "--json" in argv:
        Path(argv[argv.index("--json") + 1]).write_text(json.dumps(res), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
