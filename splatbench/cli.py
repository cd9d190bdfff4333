"""The `splatbench` command line.

Layout, in one sentence: a command lives in the ``cli.py`` of the package whose work it
runs (``bench``, ``compare``, ``conform``, ``experiments`` (run),
``reports`` (report), ``scenes``, ``stress``, ``train``, ``validate``), and the three
commands that run top-level modules or several packages (``demo``, ``render``, ``sfm``)
live in ``splatbench/commands/<name>.py``. `COMMANDS` below is the one list of commands:
adding one is a click command in the right module plus one line there.

Commands are imported only when invoked, so `splatbench --help` is instant. Every `SplatbenchError` (bad input, missing files)
is printed as one line and exits with status 2, never as a traceback. SIGTERM and
SIGINT stop a command cleanly (`splatbench.interrupt`): one line naming what was
kept, exit status 128 + the signal number.
"""

from __future__ import annotations

import errno
import importlib
import os
import sys

import click

# name -> ("module:attribute", one-line help shown by `splatbench --help`)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("splatbench.commands.demo:demo", "Run the main job and print where its output is."),
    "render": ("splatbench.commands.render:render", "Render a 3DGS PLY or workload to a PNG."),
    "stress": ("splatbench.stress.cli:stress", "Stress the rasterizer with degenerate input."),
    "bench": ("splatbench.bench.cli:bench", "Benchmarks (raster: run time, memory, throughput)."),
    "scenes": ("splatbench.scenes.cli:scenes", "Mitsuba scene catalog: list scenes, render one into a dataset."),
    "sfm": ("splatbench.commands.sfm:sfm", "Structure from motion (pycolmap) on a dataset's training views."),
    "compare": ("splatbench.compare.cli:compare", "Compare rasterizers against the float64 oracle."),
    "conform": ("splatbench.conform.cli:conform", "Check a rasterizer against 3DGS conventions (probe scenes)."),
    "snapshot": ("splatbench.regress.cli:snapshot", "Store a rasterizer's outputs and gradients on a fixed scene set."),
    "check": ("splatbench.regress.cli:check", "Check a rasterizer against its snapshot: what moved, toward or away from the oracle."),
    "validate": ("splatbench.validate.cli:validate", "Cross-check the rasterizer (mitsuba: ray-traced Gaussians)."),
    "run": ("splatbench.experiments.cli:run", "Run an experiment grid (resumable; local or Dask executor)."),
    "report": ("splatbench.reports.cli:report", "Write an experiment's report: tables, findings, figures."),
    "train": ("splatbench.train.cli:train", "Train 3DGS on a dataset (L1 + D-SSIM, SH schedule, densification)."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module, attr = COMMANDS[name][0].split(":")
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """Click's main, with a usage error (unknown option, bad value, missing argument) as one
        ``splatbench: error: ...`` line naming the command's --help, exit 2, like every other error."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.UsageError as exc:
            where = exc.ctx.command_path if exc.ctx is not None else "splatbench"
            click.echo(f"splatbench: error: {exc.format_message()} (see '{where} --help')", err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            click.echo("Aborted!", err=True)
            sys.exit(1)
        except click.exceptions.Exit as exc:
            sys.exit(exc.exit_code)

    def invoke(self, ctx: click.Context):
        from splatbench.errors import SplatbenchError
        from splatbench.interrupt import Interrupted, stop_on_signals

        try:
            with stop_on_signals():
                return super().invoke(ctx)
        except SplatbenchError as exc:
            click.echo(f"splatbench: error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # a file-system fault: a read-only folder, a full disk, a path of the wrong type
            click.echo(f"splatbench: error: {os_error_line(exc)}", err=True)
            sys.exit(2)
        except Interrupted as exc:
            click.echo(f"splatbench: {exc.line()}", err=True)
            # what was kept is on disk and closed; skip the interpreter's teardown of torch
            # and Dr.Jit (seconds), so that a batch system's grace period is not spent on it
            sys.stdout.flush()
            sys.stderr.flush()
            _release_semaphores()
            os._exit(exc.exit_status)


def _release_semaphores() -> None:
    """Unlink the named semaphores multiprocessing still holds (a stopped process pool's queue
    locks) before a fast exit: the interpreter's teardown, which would, is skipped, and the
    resource tracker would then print "There appear to be N leaked semaphore objects" after the
    one line. Runs multiprocessing's own finalizers of exit priority >= 0 (where SemLock
    registers its unlink), as its atexit function does first; `multiprocessing.util` has no
    public form of it."""
    util = sys.modules.get("multiprocessing.util")
    if util is None:
        return
    try:
        util._run_finalizers(0)
    except Exception:  # noqa: BLE001 - best effort on the way out; the exit must happen
        pass


_OS_FIXES = {
    errno.EACCES: "make it writable (or readable) or choose another path",
    errno.EPERM: "make it writable (or readable) or choose another path",
    errno.EROFS: "the file system is read-only; choose another path",
    errno.ENOSPC: "no space left; free some or choose another path",
    errno.EDQUOT: "disk quota exceeded; free some or choose another path",
    errno.EISDIR: "it is a folder; give a file path",
    errno.ENOTDIR: "a part of the path is a file, not a folder; choose another path",
    errno.EEXIST: "it exists; remove it or choose another path",
    errno.ENOENT: "it does not exist; check the path",
}


def os_error_line(exc: OSError) -> str:
    """``PATH: what went wrong; the fix`` for a file-system error, in one line."""
    where = exc.filename if exc.filename is not None else "file system"
    what = (exc.strerror or str(exc)).strip().splitlines()[0] if (exc.strerror or str(exc)).strip() else "I/O error"
    fix = _OS_FIXES.get(exc.errno or -1)
    return f"{where}: {what}" + (f" ({fix})" if fix else "")


@click.group(cls=LazyGroup)
@click.version_option(package_name="splatbench")
def main() -> None:
    """splatbench: compare and validate 3D Gaussian Splatting rasterizers."""
