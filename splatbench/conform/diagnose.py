"""From failing probes to root causes: which conventions the backend follows (fingerprinting), and the
defects that remain.

Fingerprinting (`fingerprint`). In two stages, the basic probes first, then every probe: for the
probes that fail, each alternative value of each axis of the convention vocabulary
(`splatbench.backends.base.AXES`, most basic first) is tried in the oracle, and scored by the failing
probes it makes pass: on the basic stage, forward probes only (the gradient probes for "detached", the
one axis that changes gradients only); after it, outputs and gradients, but only for candidates that
make a probe isolating their axis pass (a convention that differs always fails, or warns in, those).
The best candidate is kept when, with every probe rerun against the oracle under it (outputs and
gradients), fewer probes fail and none that passed fails; then the search repeats. When
no single alternative explains a failing basic probe, pairs of alternatives are tried on the basic
probes; when still nothing, a greedy multi-axis step (`_greedy`: add the alternative that most
reduces the failing forward probes' excess over their tolerances, repeat, at most GREEDY_AXES axes).
Candidates explaining as many probes are told apart by that excess. The probe scenes are tiny, so
the search costs a few dozen small renders per axis.

Root causes (`root_causes`). The failing probes whose scene the backend draws (nearly) nothing of,
where the oracle draws, are one defect of their own (a cull outside the vocabulary, a zero opacity:
`evidence.undrawn`), whatever each probe isolates. Of the rest, each probe isolates one feature (its name) and exercises others (a
scene with two Gaussians exercises the depth order, an anisotropic rotated one the quaternion order,
a gradient of means the conic's gradient, ...: `exercises`). The defects are the smallest set of
failing probes whose features account for every failing probe (ties: the set whose features the
fewest passing probes exercise, then the earliest probes); each lists the failing probes that follow
from it. A probe isolating a convention axis that every scene exercises (the pixel centre, the
activations, eps2d, alpha_min) links other probes to itself only when the evidence supports its cause
(an alternative value of its axis halves its deviation); a root whose cause is not supported is
reported as "unexplained: <what differs>" (`evidence.describe`: coverage, centroid, orientation,
size, mirror image), not under the probe's usual cause.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from splatbench.backends.base import AXES, AXIS
from splatbench.verification.calls import Fault
from splatbench.conform.evidence import coverage, describe, undrawn
from splatbench.conform.judges import JUDGES, Context, _backend_outputs, _compared, _pixel_diff
from splatbench.conform.oracle import oracle, projection
from splatbench.conform.probes import AXIS_PROBES, BASIC, Probe

AXIS_OF: dict[str, str] = {}  # probe -> the first axis it isolates
for _axis, _names in AXIS_PROBES.items():
    for _name in _names:
        AXIS_OF.setdefault(_name, _axis)
from splatbench.conform.results import ProbeResult
from splatbench.render_inputs import RenderInput

#: The cause given when the backend fails on a probe's scene (raises, bad shape, NaN), where the
#: probe's own convention cannot be judged.
FAULT_CAUSE = "the backend failed on this probe's scene (see measured), so the convention could not be judged"
#: The cause of a defect grouping the probes on whose valid scenes the backend fails the same way.
FAULT_DEFECT = "the backend fails on a valid scene"
OK = ("pass", "warn", "skip")
#: Features every probe scene exercises: a wrong pixel centre, activation, low-pass or skip changes any render.
EVERYWHERE = ("pixel_centre", "scale_activation", "opacity_activation", "eps2d", "alpha_min")
#: Probes isolating a convention axis whose cause must be backed by the evidence (`_supported`) before they
#: account for other failures: the EVERYWHERE ones, and expected_depth, whose depth output every scene of two
#: or more Gaussians changes when they are composited in the wrong order (a sort on camera x, say) -- a wrong
#: order is no wrong depth formula, and only a value of the `depth` axis reproducing the backend says it is.
AXIS_CHECKED = (*EVERYWHERE, "expected_depth")
#: The basic probe every other one builds on: one plain Gaussian (a failure there can explain any other).
CORE = "basic_centred"
TAIL_D2 = 4.0  # a footprint's "tail": beyond 2 sigma, where a cutoff other than the declared one shows
MAX_ROOTS = 3  # exhaustive cover search up to this size, greedy beyond
GREEDY_AXES = 6  # the most axes the greedy multi-axis search changes at once


@dataclass(frozen=True)
class Finding:
    """A convention found to differ from the declared one: ``axis`` is ``found``, not ``expected``;
    ``explains``: the probes that fail under the declaration and pass under the finding."""

    axis: str
    expected: Any
    found: Any
    explains: tuple[str, ...]
    alike: tuple = ()  # other values of the axis the probes cannot tell from ``found`` (same verdicts)


@dataclass(frozen=True)
class Defect:
    """A failing probe no convention explains, with the other failing probes that follow from it."""

    probe: str
    cause: str
    deviation: float | None
    tolerance: float | None
    follows: tuple[str, ...]


def run_probes(selected: tuple[Probe, ...], ctx: Context) -> dict[str, ProbeResult]:
    """Every probe in ``selected`` judged against the oracle under ``ctx.conv``."""
    out = {}
    for probe in selected:
        out[probe.name] = judge(probe, ctx)
    return out


def judge(probe: Probe, ctx: Context) -> ProbeResult:
    s = probe.build()
    try:
        return JUDGES[probe.kind](probe, s, ctx)
    except Fault as fault:
        return ProbeResult(probe.name, probe.kind, "fail", probe.checks, None, None, "", str(fault), FAULT_CAUSE)


def _failing(results: dict[str, ProbeResult], names=None) -> list[str]:
    return [n for n, r in results.items() if r.status == "fail" and (names is None or n in names)]


def _candidates(conv: dict, changed: set[str]):
    """Each single change {axis: value} to ``conv`` on an axis not yet diagnosed, in the vocabulary's order."""
    for axis in AXES:
        if axis.name in changed:
            continue
        for value in (axis.graphdeco, *axis.alternatives):
            if value != conv[axis.name]:
                yield {axis.name: value}


def _explained(probes: list[Probe], ctx: Context, change: dict, *, forward_only: bool = False) -> list[str]:
    """The probes (all failing under ctx.conv) that pass, or only warn, under ctx.conv + change.
    ``forward_only``: judge the forward probes only (a cheap first look: no finite differences)."""
    return _trial(probes, ctx, change, forward_only=forward_only)[0]


def _trial(probes: list[Probe], ctx: Context, change: dict, *, forward_only: bool = False) -> tuple[list[str], float]:
    """(`_explained`, the excess left: the sum over the judged probes of log(deviation / tolerance) where
    above 1), the excess telling apart candidates that explain the same probes."""
    gradient_only = change == {"sh_view_direction": "detached"}  # the same forward: only gradients can tell
    trial = dataclasses.replace(ctx, conv={**ctx.conv, **change})
    out, excess = [], 0.0
    for p in probes:
        gradient = p.kind in ("gradient", "direction")
        if (gradient and forward_only and not gradient_only) or (gradient_only and not gradient):
            continue
        r = judge(p, trial)
        if r.status in OK:
            out.append(p.name)
        excess += _excess(p, r, trial)
    return out, excess


def _excess(probe: Probe, r: ProbeResult, ctx: Context) -> float:
    """How far a probe is from passing: for forward probes the mean over pixels of log(difference /
    tolerance) where above 1 (every pixel counts, so removing one of several differences shows even
    where another sets the largest one); else log(deviation / tolerance); a fault: a large constant."""
    if r.status in OK:
        return 0.0
    if r.deviation is None or r.tolerance is None or not r.tolerance > 0:
        return 50.0
    outputs = _compared(probe, ctx)
    if probe.kind in ("forward", "approximation") and outputs:
        s, key = probe.build(), probe.build.__name__
        diff = _pixel_diff(_backend_outputs(s, key, ctx), oracle(key, s, ctx.conv), outputs)
        return float(np.log(np.maximum(diff / r.tolerance, 1.0)).mean())
    return float(np.log(max(r.deviation / r.tolerance, 1.0)))


def _isolates(change: dict, failing: list[Probe], warned: list[Probe], ctx: Context) -> bool:
    """Whether ``change`` makes a failing probe isolating its axis pass (or warn), or a warning one pass:
    a convention that differs always shows in those probes."""
    axis = next(iter(change))
    own = [p for p in failing if p.name in AXIS_PROBES[axis]]
    if own and _explained(own, ctx, change):
        return True
    trial = dataclasses.replace(ctx, conv={**ctx.conv, **change})
    return any(judge(p, trial).status == "pass" for p in warned if p.name in AXIS_PROBES[axis])


def fingerprint(selected: tuple[Probe, ...], ctx: Context,
                results: dict[str, ProbeResult]) -> tuple[dict, list[Finding], dict[str, ProbeResult]]:
    """Search the vocabulary for the conventions that explain the failing probes (module docstring).

    Returns the conventions found (a conform conventions mapping), the findings in the order found,
    and every probe's result under those conventions."""
    by_name = {p.name: p for p in selected}
    declared, conv, findings, changed = dict(ctx.conv), dict(ctx.conv), [], set()
    stages = [tuple(n for n in BASIC if n in by_name), tuple(by_name)]
    for stage in stages:
        rejected: list[dict] = []
        while True:
            # a probe the backend faults on (raises, NaN) says nothing of conventions: no candidate can explain it
            failing = [by_name[n] for n in _failing(results, stage) if results[n].cause != FAULT_CAUSE]
            if not failing:
                break
            here = dataclasses.replace(ctx, conv=conv)
            scored = []
            warned = [by_name[n] for n in stage if results[n].status == "warn"]
            for change in _candidates(conv, changed):
                if change in rejected:
                    continue
                if stage is stages[0]:
                    explains, excess = _trial(failing, here, change, forward_only=True)
                elif _isolates(change, failing, warned, here):
                    # A convention that differs fails (or warns in) the probes isolating its axis: one that
                    # does not make them pass cannot be it. Those that do are scored on outputs and gradients.
                    explains, excess = _trial(failing, here, change)
                else:
                    continue
                if explains:
                    scored.append(((len(explains), -excess), change))
            if not scored and stage is stages[0]:
                scored = _pairs(failing, here, changed, rejected)
            if not scored:
                scored = _greedy(failing, here, changed, rejected)
            if not scored:
                break
            # the most probes explained, then the least excess left; first of equals: the vocabulary's order
            best = max(scored, key=lambda sc: sc[0])[1]
            trial_results = run_probes(selected, dataclasses.replace(ctx, conv={**conv, **best}))
            before, after = set(_failing(results)), set(_failing(trial_results))
            if len(after) >= len(before) or after - before:
                rejected.append(best)
                continue
            explains = tuple(n for n in by_name if n in before and n not in after)
            for axis, value in best.items():
                findings.append(Finding(axis, declared[axis], value, explains))
                changed.add(axis)
            conv, results = {**conv, **best}, trial_results
    if len(findings) >= 2:
        conv, findings, results = _refine(selected, ctx, conv, findings, results)
    return conv, findings, results


def _refine(selected: tuple[Probe, ...], ctx: Context, conv: dict, findings: list[Finding],
            results: dict[str, ProbeResult]):
    """One pass over the axes found, each set to the value of its axis that leaves the forward probes the
    least excess with the other findings in place (a value found early, before the others, may be only
    the nearest to the truth: 0.999 for a backend clamping at 1 while its cutoff still differed). Kept
    when every probe rerun under it fails no more than before."""
    forward = [p for p in selected if p.kind in ("forward", "approximation")]
    here = dataclasses.replace(ctx, conv=conv)
    left = _trial(forward, here, {}, forward_only=True)[1]
    change: dict = {}
    alike: dict[str, list] = {}
    for fd in findings:
        for value in (AXIS[fd.axis].graphdeco, *AXIS[fd.axis].alternatives):
            if value not in (conv[fd.axis], ctx.conv[fd.axis]):
                excess = _trial(forward, here, {**change, fd.axis: value}, forward_only=True)[1]
                if excess < left:
                    left, change = excess, {**change, fd.axis: value}
                    alike[fd.axis] = []
                elif excess == left:
                    alike.setdefault(fd.axis, []).append(value)
    findings = [dataclasses.replace(fd, alike=tuple(alike.get(fd.axis, ()))) for fd in findings]
    if not change:
        return conv, findings, results
    trial_results = run_probes(selected, dataclasses.replace(ctx, conv={**conv, **change}))
    before, after = set(_failing(results)), set(_failing(trial_results))
    if len(after) > len(before) or after - before:
        return conv, findings, results
    return ({**conv, **change}, [dataclasses.replace(fd, found=change.get(fd.axis, fd.found)) for fd in findings],
            trial_results)


def _pairs(failing: list[Probe], ctx: Context, changed: set[str], rejected: list[dict]) -> list:
    """Two alternatives at once, scored on the failing basic probes (each alone explained none)."""
    singles = list(_candidates(ctx.conv, changed))
    scored = []
    for a, b in itertools.combinations(singles, 2):
        if set(a) & set(b) or {"sh_view_direction": "detached"} in (a, b):
            continue
        change = {**a, **b}
        if change in rejected or not _explained(failing[:1], ctx, change, forward_only=True):
            continue  # the first probe rules most pairs out
        explains, excess = _trial(failing, ctx, change, forward_only=True)
        if explains:
            scored.append(((len(explains), -excess), change))
    return scored


def _greedy(failing: list[Probe], ctx: Context, changed: set[str], rejected: list[dict]) -> list:
    """Several axes at once, when no single alternative (nor pair) makes a failing probe pass: a dense
    renderer differs from graphdeco on several approximations at once (no alpha skip, no clamp, no
    cutoff, no early stop), each probe showing more than one. Greedy on the forward probes: add the
    alternative that most reduces the excess left (`_excess`), repeat while it falls by a tenth or
    more, at most GREEDY_AXES axes (each step a few dozen renders of the tiny failing scenes); then
    one pass over the axes taken, each set to its value that leaves the least excess given the others."""
    forward = [p for p in failing if p.kind in ("forward", "approximation")]
    if not forward:
        return []
    change: dict = {}
    left = _trial(forward, ctx, change, forward_only=True)[1]
    while len(change) < GREEDY_AXES and left > 0:
        best = None
        for single in _candidates({**ctx.conv, **change}, changed | set(change)):
            if single == {"sh_view_direction": "detached"}:
                continue
            excess = _trial(forward, ctx, {**change, **single}, forward_only=True)[1]
            if excess < 0.9 * left and (best is None or excess < best[0]):
                best = (excess, single)
        if best is None:
            break
        left, change = best[0], {**change, **best[1]}
    for axis in list(change):  # one pass of refinement: a value taken early may be bettered with the rest set
        for value in (AXIS[axis].graphdeco, *AXIS[axis].alternatives):
            if value != change[axis]:
                excess = _trial(forward, ctx, {**change, axis: value}, forward_only=True)[1]
                if excess < left:
                    left, change = excess, {**change, axis: value}
    change = {k: v for k, v in change.items() if v != ctx.conv[k]}
    if len(change) < 2 or change in rejected:
        return []
    explains = _explained(forward, ctx, change, forward_only=True)
    return [((len(explains), -left), change)] if explains else []


# ----------------------------------------------------------------------------
# Root causes of what no convention explains
# ----------------------------------------------------------------------------

def exercises(probe: Probe, s: RenderInput, conv: dict) -> frozenset[str]:
    """The features (named by the probe that isolates each) a probe's verdict depends on."""
    import reference

    f = {probe.name, *EVERYWHERE, CORE}
    cam = s.camera
    groups = set(probe.groups) if probe.kind == "gradient" else \
        {"log_scales", "quats"} if probe.kind == "direction" else set()
    if len(s.means) >= 2:
        f.add("depth_order")
    scales = np.exp(s.log_scales)
    qn = np.linalg.norm(s.quats, axis=1)
    rotated = np.abs(np.abs(s.quats[:, 0]) / qn - 1) > 1e-6
    if ((scales.max(1) / scales.min(1) > 1.05) & rotated).any():
        f.add("quat_order")
    if (np.abs(qn - 1) > 1e-3).any() or "quats" in groups:
        f.add("quat_norm")
    available = {1: 0, 4: 1, 9: 2, 16: 3}[s.sh.shape[1]]
    degree = available if s.sh_degree is None else s.sh_degree
    for band in range(1, degree + 1):
        if np.abs(s.sh[:, band * band:(band + 1) ** 2]).max() > 0:
            f.update((f"sh_degree{band}", "sh_viewdir"))
    if s.sh_degree is not None:
        f.add("sh_degree_arg")
    if "means" in groups and "sh_viewdir" in f:
        f.add("sh_viewdir_grad")
    dirs = s.means - reference.camera_centre(cam.world_to_camera)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    colour = np.einsum("nk,nkc->nc", reference.sh_basis(dirs, degree), s.sh[:, :(degree + 1) ** 2]) + 0.5
    if (colour < 0).any() or (colour > 1).any():
        f.add("colour_clamp")
    if s.background is not None and any(b != 0 for b in s.background):
        f.add("background")
    if "depth" in probe.outputs and probe.kind in ("forward", "approximation") or groups:
        f.add("expected_depth")
    if cam.fx != cam.fy or cam.cx != cam.width / 2 or cam.cy != cam.height / 2:
        f.add("intrinsics")
    t = s.means @ cam.rotation.T + cam.translation
    if (t[:, 2] < cam.near).any():
        f.add("near_plane")
    front = t[:, 2] > 0
    u = cam.fx * t[front, 0] / t[front, 2] + cam.cx
    v = cam.fy * t[front, 1] / t[front, 2] + cam.cy
    if cam.width > 16 or cam.height > 16 or ((u < 0) | (u > cam.width) | (v < 0) | (v > cam.height)).any():
        f.add("tiles")
    if ((u < -0.15 * cam.width) | (u > 1.15 * cam.width) | (v < -0.15 * cam.height) | (v > 1.15 * cam.height)).any():
        f.add("jacobian_clamp")
    proj = projection(s, conv)
    d2, raw = _contributions(s, proj)
    keep = raw >= conv["alpha_min"]
    if (keep & (d2 > TAIL_D2)).any():
        f.add("radius")
    if (np.cumprod(1 - np.minimum(raw, conv["alpha_max"]) * keep, axis=1) < 1e-4).any():
        f.add("early_stop")
    if (proj.opacities > AXIS["alpha_max"].graphdeco).any():
        f.add("alpha_max")
        if groups:
            f.add("alpha_max_grad")
    f.update(f"grad_{g}" for g in groups)
    if groups & {"means", "log_scales", "quats"}:
        f.update(("conic_A", "conic_B", "conic_C"))
    return frozenset(f)


def _contributions(s: RenderInput, proj) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel and visible Gaussian (depth order): Mahalanobis d^2 [P, M] and raw alpha o exp(-d^2 / 2)."""
    c = s.camera
    vis = np.flatnonzero(proj.visible)
    vis = vis[np.argsort(proj.depths[vis], kind="stable")]
    jj, ii = np.meshgrid(np.arange(c.width) + 0.5, np.arange(c.height) + 0.5)
    dx = jj.reshape(-1, 1) - proj.means2d[vis, 0]
    dy = ii.reshape(-1, 1) - proj.means2d[vis, 1]
    A, B, C = proj.conics[vis].T
    d2 = A * dx * dx + C * dy * dy + 2 * B * dx * dy
    return d2, proj.opacities[vis] * np.exp(-d2 / 2)


def root_causes(selected: tuple[Probe, ...], results: dict[str, ProbeResult], ctx: Context) -> list[Defect]:
    """The defects behind the probes failing under ``ctx.conv`` (module docstring): the smallest set of
    failing probes whose features account for every failing probe the backend draws something of; among sets of that size, the one whose features the
    fewest passing probes exercise (a defect in a feature fails the probes that use it), then the earliest.
    A probe isolating a convention axis reaches other probes through that feature only when the evidence
    supports its cause (`_supported`); a root whose cause is not supported is "unexplained: <what differs>".
    The probes whose scene the backend draws (nearly) nothing of join a root whose own feature they
    exercise, else form one defect of their own (first when it is the largest)."""
    conv = ctx.conv
    failing = [p for p in selected if results[p.name].status == "fail"]
    faulted = [p for p in failing if results[p.name].cause == FAULT_CAUSE]
    failing = [p for p in failing if results[p.name].cause != FAULT_CAUSE]
    faults = _fault_defects(faulted, results)
    if not failing:
        return faults
    by_name = {p.name: p for p in selected}
    empty = [p.name for p in failing if _undrawn(p, ctx)]
    names = [p.name for p in failing if p.name not in empty]
    uses = {p.name: set(exercises(p, p.build(), conv)) for p in selected
            if results[p.name].status in ("fail", "pass")}
    claimed = {n: _supported(by_name[n], results[n], ctx) for n in names}
    weak = {f for f in AXIS_CHECKED if f in claimed and claimed[f] is not None}  # a cause the evidence does not back
    for n, f in uses.items():
        f -= weak - {n}
    passing = [n for n in uses if results[n].status == "pass"]

    def covers(root: str) -> set[str]:
        return {n for n in names if root in uses[n]}

    def contradictions(combo) -> int:
        return sum(any(r in uses[n] for r in combo) for n in passing)

    chosen = None
    for size in range(1, min(MAX_ROOTS, len(names)) + 1):
        covering = [combo for combo in itertools.combinations(names, size)
                    if set().union(*(covers(r) for r in combo)) == set(names)]
        if covering:
            chosen = list(min(covering, key=contradictions))  # min keeps the earliest of equals
            break
    if not names:
        chosen = []
    elif chosen is None:  # greedy: the root covering most of what is left, earliest first
        chosen, left = [], set(names)
        while left:
            best = max(names, key=lambda r: (len(covers(r) & left), -names.index(r)))
            chosen.append(best)
            left -= covers(best)
    # An empty scene goes with a root whose own feature it exercises (a Gaussian drawn only in the tile
    # of its centre leaves a scene of off-image centres empty); the rest form a defect of their own.
    specific = [r for r in chosen if r not in EVERYWHERE and r != CORE]
    attached = {e for e in empty if e != CORE and any(r in uses[e] for r in specific)}
    names += [e for e in empty if e in attached]
    defects, taken = [], set(chosen)
    for root in chosen:
        r = results[root]
        follows = tuple(n for n in names if n not in taken and root in uses[n])
        taken.update(follows)
        cause = claimed[root] if claimed[root] is not None else (r.cause or "")
        defects.append(Defect(root, cause, r.deviation, r.tolerance, follows))
    empty = [e for e in empty if e not in attached]
    if CORE in empty:  # the single plain Gaussian is not drawn: everything else may follow from that
        empty = list(dict.fromkeys([CORE, *(n for n in [p.name for p in failing] if n != CORE)]))
        defects = []
    if empty:
        want = have = 0
        for key in dict.fromkeys(by_name[n].build.__name__ for n in empty):
            s = next(p for p in failing if p.build.__name__ == key).build()
            w, h = coverage(_backend_outputs(s, key, ctx), oracle(key, s, conv), _has_alpha(ctx))
            want, have = want + w, have + h
        r = results[empty[0]]
        blank = Defect(empty[0], f"{UNDRAWN_CAUSE} (on {len(empty)} failing probes: it draws {have} of the "
                                 f"{want} pixels the oracle draws)", r.deviation, r.tolerance, tuple(empty[1:]))
        # first when it accounts for at least as many failing probes as any other defect
        largest = max((1 + len(d.follows) for d in defects), default=0)
        defects = [blank, *defects] if len(empty) >= largest else [*defects, blank]
    return faults + defects


def _fault_defects(faulted: list[Probe], results: dict[str, ProbeResult]) -> list[Defect]:
    """One defect per distinct fault (the same exception at the same place), rooted at the first probe it
    fails, with the others following: a backend that raises on valid input has a defect where it raises."""
    groups: dict[str, list[str]] = {}
    for p in faulted:
        groups.setdefault(results[p.name].detail, []).append(p.name)
    return [Defect(names[0], f"{FAULT_DEFECT}: {detail}", None, None, tuple(names[1:]))
            for detail, names in groups.items()]


#: The cause of a defect whose probe scenes the backend leaves (nearly) empty.
UNDRAWN_CAUSE = ("the backend draws nothing, or nearly nothing, where the oracle draws: a cull outside the "
                 "convention vocabulary (e.g. of Gaussians large on screen), a zero opacity or a collapsed "
                 "footprint, not the probes' own features")


def _has_alpha(ctx: Context) -> bool:
    return "alpha" in ctx.backend.info.outputs


def _undrawn(probe: Probe, ctx: Context) -> bool:
    """Whether the backend draws (nearly) nothing of ``probe``'s scene where the oracle draws."""
    s = probe.build()
    try:
        got = _backend_outputs(s, probe.build.__name__, ctx)
    except Fault:
        return False
    return undrawn(got, oracle(probe.build.__name__, s, ctx.conv), _has_alpha(ctx))


def _supported(probe: Probe, result: ProbeResult, ctx: Context) -> str | None:
    """None when the failing probe's own cause stands; else the cause the evidence supports instead.

    A forward probe isolating a convention axis every scene exercises (`EVERYWHERE`: the likeliest to
    be blamed for someone else's bug) names that axis's likely departure: the cause stands
    only when some alternative value of the axis halves the probe's deviation (the oracle under it
    explains the backend better than under the declared value). Otherwise, and for the basic probes
    (whose cause defers to a diagnosis there is none of), "unexplained: <what differs>"; so is
    depth_order's when the alpha differs (no order changes it). Other forward probes keep their cause,
    with what differs appended; gradient probes and faults keep theirs."""
    if probe.kind not in ("forward", "approximation") or result.cause == FAULT_CAUSE or result.deviation is None:
        return None
    s = probe.build()
    key = probe.build.__name__
    try:
        got = _backend_outputs(s, key, ctx)
    except Fault:
        return None
    what = describe(got, oracle(key, s, ctx.conv), _has_alpha(ctx))
    axis = AXIS_OF.get(probe.name) if probe.name in AXIS_CHECKED else None
    if probe.name == "depth_order" and _has_alpha(ctx):
        # alpha = 1 - prod(1 - a_i) does not depend on the order: a wrong order leaves it right
        if float(np.abs(got[..., 3] - oracle(key, s, ctx.conv)[..., 3]).max()) > result.tolerance:
            return f"unexplained: {what} (alpha differs too, which no compositing order changes)"
    if axis is None and probe.name not in BASIC:
        return f"{result.cause}; what differs: {what}"
    if axis is not None:
        for value in (AXIS[axis].graphdeco, *AXIS[axis].alternatives):
            if value == ctx.conv[axis]:
                continue
            alt = judge(probe, dataclasses.replace(ctx, conv={**ctx.conv, axis: value}))
            if alt.deviation is not None and alt.deviation <= 0.5 * result.deviation:
                return None
        return f"unexplained: {what} (no value of `{axis}` reproduces it)"
    return f"unexplained: {what}"


def explained_by(findings: list[Finding]) -> dict[str, str]:
    """probe name -> the axis (or axes, comma-separated) whose finding explains it."""
    out: dict[str, list[str]] = {}
    for fd in findings:
        for n in fd.explains:
            out.setdefault(n, []).append(fd.axis)
    return {n: ", ".join(axes) for n, axes in out.items()}


__all__ = ["Finding", "Defect", "fingerprint", "root_causes", "run_probes", "exercises", "explained_by",
           "FAULT_CAUSE", "FAULT_DEFECT", "UNDRAWN_CAUSE"]
