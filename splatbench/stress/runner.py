"""Run stress cases through `splatbench.rasterize` (forward and backward) and classify them.

Per case: every group requires grad; the loss is a random cotangent over rgb, alpha
and depth. The contract checked (docs/conventions.md, docs/stress.md):

* non-finite input is rejected with a one-line `InputError` naming the field;
* finite input is never rejected, and never gives NaN/Inf in an output or gradient;
* any other exception is a failure.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np
import torch

from splatbench.errors import InputError
from splatbench.raster.device import get_device
from splatbench.stress.cases import CATEGORIES, FIELDS, StressCase, build_case
from splatbench.verification.cotangents import Cotangents


@dataclass(frozen=True)
class CaseResult:
    """The outcome of one case.

    culled: Gaussians with radii == 0 (0 when rejected); rejected: `InputError` raised;
    nonfinite_outputs: outputs (rgb, alpha, depth) holding NaN/Inf; nonfinite_grads:
    groups whose gradient holds NaN/Inf; error: what went wrong otherwise (another
    exception, finite input rejected, non-finite input accepted, a rejection that does
    not name the field), None when nothing did.
    """

    category: str
    seed: int
    n: int
    culled: int = 0
    rejected: bool = False
    nonfinite_outputs: tuple[str, ...] = ()
    nonfinite_grads: tuple[str, ...] = ()
    error: str | None = None
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not (self.nonfinite_outputs or self.nonfinite_grads or self.error)

    @property
    def label(self) -> str:
        return f"build_case({self.category!r}, {self.seed})"

    def describe(self) -> str:
        """One line saying what failed and how to rebuild the case."""
        parts = []
        if self.nonfinite_outputs:
            parts.append(f"non-finite outputs {list(self.nonfinite_outputs)}")
        if self.nonfinite_grads:
            parts.append(f"non-finite gradients {list(self.nonfinite_grads)}")
        if self.error:
            parts.append(self.error)
        return f"{self.label}: " + "; ".join(parts or ["ok"])


@dataclass
class CategoryReport:
    """Totals of one category.

    cases: cases run; culled: Gaussians culled (radii == 0), summed over cases;
    rejected: cases rejected with `InputError`; nonfinite_outputs / nonfinite_grads:
    cases with NaN/Inf in an output / a gradient (must be 0); errors: one line per
    unexpected outcome (see `CaseResult.error`); failures: `CaseResult.describe()` of
    every failing case, each naming how to rebuild it.
    """

    category: str
    cases: int = 0
    culled: int = 0
    rejected: int = 0
    nonfinite_outputs: int = 0
    nonfinite_grads: int = 0
    errors: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.nonfinite_outputs == 0 and self.nonfinite_grads == 0 and not self.errors

    def add(self, result: CaseResult) -> None:
        self.cases += 1
        self.culled += result.culled
        self.rejected += int(result.rejected)
        self.nonfinite_outputs += int(bool(result.nonfinite_outputs))
        self.nonfinite_grads += int(bool(result.nonfinite_grads))
        if result.error:
            self.errors.append(f"{result.label}: {result.error}")
        if not result.ok:
            self.failures.append(result.describe())


@dataclass
class StressReport:
    """All categories of one run; ``ok`` when no category has a failure."""

    categories: list[CategoryReport]
    seed: int
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.categories)

    @property
    def cases(self) -> int:
        return sum(c.cases for c in self.categories)

    def to_dict(self) -> dict:
        """JSON-ready form (the dataclass fields plus ``ok``)."""
        return {**dataclasses.asdict(self), "ok": self.ok,
                "categories": [{**dataclasses.asdict(c), "ok": c.ok} for c in self.categories]}


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def _check_rejection(case: StressCase, exc: InputError) -> str | None:
    """None when rejecting ``case`` was right and the message names the field."""
    message = str(exc)
    if case.nonfinite_field is None:
        return f"finite input rejected ({_first_line(exc)})"
    if "\n" in message.strip() or not message.startswith(f"{case.nonfinite_field}:"):
        return f"rejection does not name {case.nonfinite_field!r} in one line ({_first_line(exc)})"
    return None


def run_case(case: StressCase, *, device: str | None = None) -> CaseResult:
    """Forward and backward of ``case`` through `splatbench.rasterize`, classified."""
    from splatbench.raster import rasterize

    start = time.perf_counter()
    base = CaseResult(case.category, case.seed, case.n)
    options = case.options if device is None else dataclasses.replace(case.options, device=device)
    params = [torch.tensor(a, requires_grad=True) for a in case.params().values()]
    try:
        rgb, alpha, depth, info = rasterize(*params, case.camera, options=options)
        outputs = {"rgb": rgb, "alpha": alpha, "depth": depth}
        Cotangents.standard_normal([case.seed, 1], case.camera.height, case.camera.width).loss(rgb, alpha,
                                                                                               depth).backward()
    except InputError as exc:
        return dataclasses.replace(base, rejected=True, error=_check_rejection(case, exc),
                                   seconds=time.perf_counter() - start)
    except Exception as exc:  # noqa: BLE001 - every other exception is a recorded failure
        return dataclasses.replace(base, error=_first_line(exc), seconds=time.perf_counter() - start)
    error = None
    if case.nonfinite_field is not None:
        error = f"non-finite {case.nonfinite_field} accepted (not rejected)"
    missing = [k for k, p in zip(FIELDS, params) if p.grad is None]
    if missing:
        error = f"no gradient for {missing}"
    bad_out = tuple(k for k, v in outputs.items() if not bool(torch.isfinite(v).all()))
    bad_grad = tuple(k for k, p in zip(FIELDS, params) if p.grad is not None and not bool(torch.isfinite(p.grad).all()))
    culled = int((info.radii == 0).sum())
    return dataclasses.replace(base, culled=culled, nonfinite_outputs=bad_out, nonfinite_grads=bad_grad,
                               error=error, seconds=time.perf_counter() - start)


def case_seeds(seed: int, count: int) -> list[int]:
    """``count`` per-case seeds derived from ``seed`` (31-bit, deterministic)."""
    return [int(s) for s in np.random.SeedSequence(seed).generate_state(count, np.uint32) >> 1]


def _run_one(category: str, seed: int, device: str | None) -> CaseResult:
    return run_case(build_case(category, seed), device=device)


def _run_parallel(plan: list[tuple[str, int]], device: str | None, jobs: int,
                  done: Callable[[int, CaseResult], None]) -> None:
    """Run ``plan`` in ``jobs`` worker processes (each compiles its own kernels, which is
    where small cases spend their time); a worker that dies fails its pending cases."""
    context = multiprocessing.get_context("spawn")  # Dr.Jit and torch do not survive fork
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures = {pool.submit(_run_one, name, case_seed, device): i for i, (name, case_seed) in enumerate(plan)}
        for future in as_completed(futures):
            i = futures[future]
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - a crashed worker is a recorded failure
                name, case_seed = plan[i]
                result = CaseResult(name, case_seed, build_case(name, case_seed).n,
                                    error=f"worker process failed ({_first_line(exc)}); rerun with jobs=1")
            done(i, result)


def run(cases: int = 200, seed: int = 0, *, categories: Sequence[str] = CATEGORIES, device: str | None = None,
        jobs: int = 1, on_case: Callable[[CaseResult], None] | None = None) -> StressReport:
    """Run ``cases`` cases spread round-robin over ``categories``.

    Case i is ``build_case(categories[i % len(categories)], case_seeds(seed, cases)[i])``;
    the report does not depend on ``jobs`` (worker processes; 1 runs in this process).
    ``on_case`` is called after each case, in completion order (the CLI's progress bar).
    """
    if cases < 1:
        raise InputError(f"cases: expected a count >= 1, got {cases}")
    if jobs < 1:
        raise InputError(f"jobs: expected a count >= 1, got {jobs}")
    if not categories:
        raise InputError("categories: expected at least one category")
    for name in categories:
        if name not in CATEGORIES:
            raise InputError(f"category: expected one of {', '.join(CATEGORIES)}, got {name!r}")
    if device is not None:
        # An unknown device, or 'cuda' without a GPU, is one line here, not one failed case per case.
        get_device(device)
    plan = [(categories[i % len(categories)], s) for i, s in enumerate(case_seeds(seed, cases))]
    results: list[CaseResult | None] = [None] * cases

    def done(i: int, result: CaseResult) -> None:
        results[i] = result
        if on_case is not None:
            on_case(result)

    start = time.perf_counter()
    if jobs == 1 or cases == 1:
        for i, (name, case_seed) in enumerate(plan):
            done(i, _run_one(name, case_seed, device))
    else:
        _run_parallel(plan, device, min(jobs, cases), done)
    reports = {name: CategoryReport(name) for name in categories}
    for result in results:
        reports[result.category].add(result)
    return StressReport(list(reports.values()), seed, time.perf_counter() - start)
