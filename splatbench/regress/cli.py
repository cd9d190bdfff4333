"""`splatbench snapshot BACKEND --out DIR` and `splatbench check BACKEND --against DIR`."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from splatbench.devices import device_option


@click.command()
@click.argument("backend")
@click.option("--out", "out", required=True, type=click.Path(path_type=Path, file_okay=False),
              help="The snapshot folder (a new or empty one, or an older snapshot to replace).")
@click.option("--scenes", "scenes", default="full", show_default=True, type=click.Choice(["full", "small", "parity"]),
              help="The scene set: full (probes, synthetic, garden, a real model), small (probes, synthetic) or "
                   "parity (the rasterizer's parity scenes 0, 7, 13: splatbench's own golden snapshot).")
@click.option("--scene", "only", multiple=True,
              help="Only this scene of the set (repeatable; `check` then checks these). An unknown name lists them.")
@device_option
@click.option("--quiet", is_flag=True, help="No progress lines.")
def snapshot(backend: str, out: Path, scenes: str, only: tuple[str, ...], device: str, quiet: bool) -> None:
    """Render BACKEND on a fixed, versioned scene set and store its outputs and gradients in DIR.

    BACKEND: a built-in name, an installed entry point, or module:function. The snapshot
    (NumPy .npz + JSON, no pickle; docs/regression.md) holds rgb, alpha, depth and the
    gradients of seeded random cotangents per scene, the oracle's bands that set the
    tolerances, the declared conventions, package versions and device. Deterministic: two
    snapshots of the same code are equal, byte for byte.
    """
    from splatbench.regress.files import snapshot as take

    path = take(backend, out, scenes=scenes, only=only or None, device=device,
                progress=None if quiet else (lambda line: click.echo(line, err=True)))
    click.echo(f"snapshot: {path}")


@click.command()
@click.argument("backend")
@click.option("--against", "against", required=True, type=click.Path(path_type=Path),
              help="A snapshot folder written by `splatbench snapshot`.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of the table.")
@click.option("--save-images", "save_dir", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="Write SCENE_QUANTITY_{now,snapshot,difference}.png of every changed output here.")
@click.option("--scene", "scenes", multiple=True, help="Check only this scene (repeatable).")
@click.option("--no-diagnose", is_flag=True, help="Do not run conform for the cause of a regression.")
@device_option
@click.option("--quiet", is_flag=True, help="No progress lines.")
def check(backend: str, against: Path, as_json: bool, save_dir: Path | None, scenes: tuple[str, ...],
          no_diagnose: bool, device: str, quiet: bool) -> None:
    """Check BACKEND now against the snapshot in DIR: what moved, where, by how much, and whether it
    moved toward the float64 oracle (improvement) or away from it (regression).

    Exit status: 0 when every quantity is unchanged or improved, 1 on a regression or a
    convention change, 2 on bad input (no or a damaged snapshot, another scene-set version, a
    backend that cannot be called).
    """
    from splatbench.regress.against_snapshot import check as run_check

    report = run_check(backend, against, device=device, scenes=scenes or None,
                       diagnose=not no_diagnose, save_images=save_dir,
                       progress=None if (quiet or as_json) else (lambda line: click.echo(line, err=True)))
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=1, default=str))
    else:
        click.echo(format_report(report))
    sys.exit(report.exit_code)


SHOWN = 12  # rows printed per verdict (the largest changes first); --json has them all


def format_report(report) -> str:
    """The changed quantities by verdict (the largest first, `SHOWN` of each), what conform says once,
    and one summary line."""
    counts = report.counts()
    lines = [f"check {report.backend} {report.version} against {report.against} (snapshot of "
             f"{report.snapshot_backend}; scene set {report.scene_set}, {len({r.scene for r in report.results})} "
             f"scenes, {len(report.results)} quantities)"]
    lines += [f"note: {n}" for n in report.notes]
    suffix = f"; {report.conform}" if report.conform else ""
    for status in ("regression", "convention change", "improvement"):
        rows = [r for r in report.results if r.status == status]
        if not rows:
            continue
        rows.sort(key=lambda r: -(r.difference / r.tolerance) if r.difference is not None and r.tolerance else
                  -float("inf"))
        lines.append("")
        lines.append({"regression": "REGRESSIONS", "convention change": "CONVENTION CHANGES",
                      "improvement": "improvements"}[status] + f" ({len(rows)}, the largest first):")
        shown = _per_scene_faults(rows)
        lines += [f"  {line.removesuffix(suffix)}" for line in shown[:SHOWN]]
        if len(shown) > SHOWN:
            lines.append(f"  ... and {len(shown) - SHOWN} more (--json lists every quantity)")
    if report.conform:
        lines.append("")
        lines.append(f"{report.conform.replace('conform: ', 'conform on the backend now: ', 1)}")
    lines.append("")
    lines.append(f"{report.backend}: {report.status}: {counts['unchanged']} unchanged, {counts['improvement']} "
                 f"improved, {counts['regression']} regressed, {counts['convention change']} convention changes"
                 + (f"; the declared conventions changed ({', '.join(report.declared_changes)}): take the snapshot "
                    f"again if that is intended" if report.declared_changes else "")
                 + f" ({report.seconds:.1f} s)")
    return "\n".join(lines)


def _per_scene_faults(rows) -> list[str]:
    """One line per row, except that the quantities of a scene failing for one cause (a backend that
    raised on it) are one line for the scene, where the first of them stood."""
    out: list[str] = []
    groups: dict[tuple[str, str], list] = {}
    for r in rows:
        if r.difference is None:
            key = (r.scene, r.cause)
            if key not in groups:
                groups[key] = []
                out.append(key)
            groups[key].append(r)
        else:
            out.append(r.line())
    lines = []
    for entry in out:
        if isinstance(entry, str):
            lines.append(entry)
            continue
        group = groups[entry]
        if len(group) == 1:
            lines.append(group[0].line())
        else:
            lines.append(f"{entry[0]} ({len(group)} quantities): {group[0].status}: {entry[1]}")
    return lines
