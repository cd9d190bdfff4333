"""Rerun `splatbench conform` on third-party 3DGS rasterizers from PyPI and write reports/conform_public/.

    python tools/conform_public.py            # every package in PACKAGES (what `make conform-public` runs)
    python tools/conform_public.py litesplat  # one of them

Each package is installed with `pip install --no-deps --target out/conform_public/site-NAME` at a
pinned version (nothing enters the project's environment), put on PYTHONPATH beside this checkout
(for examples/adapters/), and checked with `python -m splatbench conform ADAPTER --json`. The JSON
goes to reports/conform_public/NAME/conform.json; the table between the markers of
reports/conform_public/README.md is rewritten from those files. The per-package report.md files are
written by hand (what the numbers mean, with file and line in the package's source).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's splatbench, as the conform runs below get it (PYTHONPATH)
from splatbench.report_files import markdown_table, write_json, write_text  # noqa: E402

REPORTS = ROOT / "reports" / "conform_public"
SITES = ROOT / "out" / "conform_public"
BEGIN, END = "<!-- BEGIN:table -->", "<!-- END:table -->"


@dataclass(frozen=True)
class Package:
    name: str          # folder under reports/conform_public/
    spec: str          # what `splatbench conform` is given
    requirements: tuple[str, ...] = ()   # pinned, installed --no-deps into out/conform_public/site-NAME
    env: dict = field(default_factory=dict)
    note: str = ""


PACKAGES = (
    Package("gsplat", "gsplat", (), {}, "built-in backend: gsplat's PyTorch path (`gsplat[torch]` extra of splatbench)"),
    Package("metal-gauss", "examples.adapters.metal_gauss:render", ("metal-gauss==0.2.1",)),
    Package("litesplat", "examples.adapters.litesplat:render",
            ("litesplat==0.1.1", "keras==3.15.1", "absl-py==2.5.1", "namex==0.1.0", "optree==0.20.0",
             "ml-dtypes==0.6.0", "h5py==3.16.0"), {"KERAS_BACKEND": "torch"}),
)


def install_command(p: Package) -> str:
    if not p.requirements:
        return "(in splatbench's environment: `make setup`)"
    return f"pip install --no-deps --target out/conform_public/site-{p.name} " + " ".join(p.requirements)


def install(p: Package) -> Path | None:
    """The package's target folder, installed if its pinned requirements are not there yet."""
    if not p.requirements:
        return None
    target = SITES / f"site-{p.name}"
    stamp = target / ".requirements"
    wanted = "\n".join(p.requirements)
    if not (stamp.exists() and stamp.read_text() == wanted):
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--upgrade",
                        "--target", str(target), *p.requirements], check=True)
        stamp.write_text(wanted)
    return target


def run(p: Package) -> dict:
    target = install(p)
    env = dict(os.environ, **p.env)
    env["PYTHONPATH"] = os.pathsep.join(str(x) for x in (ROOT, target) if x is not None)
    proc = subprocess.run([sys.executable, "-m", "splatbench", "conform", p.spec, "--json"],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"conform {p.spec} exited {proc.returncode}: {proc.stderr.strip()}")
    report = json.loads(proc.stdout)
    report["exit_status"] = proc.returncode
    report["install"] = install_command(p)
    write_json(REPORTS / p.name / "conform.json", report, indent=1)
    return report


def _row(p: Package, r: dict) -> list[str]:
    s = r["summary"]
    counts = f'{s["pass"]} / {s["explained"]} / {s["warn"]} / {s["fail"]} / {s["skip"]}'
    diag = "; ".join(f'`{d["axis"]}`: {d["found"]}' + "".join(f" or {v}" for v in d.get("alike", []))
                     + f' (expected {d["expected"]}, explains {len(d["explains"])})' for d in r["diagnosis"]) or "none"
    defects = "; ".join(f'`{d["probe"]}` (+{len(d.get("follows", []))} follow): {_short(d["cause"])}'
                        for d in r["defects"]) or "none"
    return [f"[{p.name}]({p.name}/report.md)", r["version"], f"`{p.spec}`", r["exit_status"], counts, diag, defects]


def _short(cause: str, limit: int = 110) -> str:
    """A defect's cause for a table cell: its first clause, at most ``limit`` characters."""
    first = cause.split(" (on ")[0].split("; what differs")[0]
    return first if len(first) <= limit else first[:limit - 3].rstrip() + "..."


def table() -> str:
    return markdown_table(["package", "version", "conform spec", "exit", "pass / explained / warn / fail / skip",
                           "diagnosis", "defects"],
                          [_row(p, json.loads(f.read_text())) for p in PACKAGES
                           if (f := REPORTS / p.name / "conform.json").exists()])


def write_table() -> None:
    readme = REPORTS / "README.md"
    text = readme.read_text()
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    write_text(readme, f"{head}{BEGIN}\n{table()}\n{END}{tail}")


def main(argv: list[str]) -> int:
    names = set(argv) or {p.name for p in PACKAGES}
    unknown = names - {p.name for p in PACKAGES}
    if unknown:
        raise SystemExit(f"conform_public: unknown package {sorted(unknown)}; one of {[p.name for p in PACKAGES]}")
    for p in PACKAGES:
        if p.name in names:
            r = run(p)
            print(f"{p.name} {r['version']}: exit {r['exit_status']}, {r['summary']}")
    write_table()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
