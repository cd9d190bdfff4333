"""The splatbench pytest plugin: conform's probes and a snapshot's quantities as pytest items.

    pytest --splatbench-backend mypkg.rast:render                       # one item per conform probe
    pytest --splatbench-backend mypkg.rast:render --splatbench-against snap/   # + one per snapshot quantity
    pytest --splatbench-backend splatbench.backends.builtins.drjit_backend:make_drjit_backend   # a built-in
    pytest --splatbench-backend drjit                                   # the same, by its registered name

Registered as the ``pytest11`` entry point ``splatbench``, so installing splatbench is all; from
a source checkout that is not installed, add ``-p splatbench.regress.pytest_plugin``. Inert
unless ``--splatbench-backend`` is given: it adds its options and one fixture, imports nothing
heavy and collects nothing. Given, it adds items ``splatbench::conform::PROBE``, and with a
snapshot ``splatbench::check::SCENE::QUANTITY`` and ``splatbench::check::declared_conventions``
(the declaration is the snapshot's), to whatever else pytest collects (``-k splatbench`` runs
only them; node ids are relative to the folder pytest runs in, as a test file's are). They are
collected as pytest collects any test (``--collect-only`` lists and counts them), and in JUnit
XML (``--junitxml``) their class name is the node id's path (``splatbench.conform``,
``splatbench.check.SCENE``). conform and check each run once, on the first item that needs
them. A failing item says conform's one-line root cause (or check's line: what moved, by how
much, toward or away from the oracle). A backend that cannot be loaded, or a missing or damaged
snapshot, is a usage error of pytest (one line, exit 4), never a pass.

Fixture ``splatbench_scene``: check a project's own scene against the float64 oracle::

    def test_my_scene(splatbench_scene):
        splatbench_scene(means, log_scales, quats, opacity_logits, sh, camera)   # backend: the option's
        splatbench_scene(..., camera, backend="mypkg.rast:render", sh_degree=1)  # or given here

It renders the scene with the backend and with the oracle (matched to the backend's declared
conventions) and fails, in one line and without a traceback, when an output differs by more
than the float32 bound outside the boundary band, or a gradient (random cotangents) by more
than its bound outside the gradient band (`splatbench.regress.measure`), or the backend raises
or cannot be loaded.
"""

from __future__ import annotations

import pytest

_STATE_KEY = "_splatbench_state"


def pytest_addoption(parser) -> None:
    group = parser.getgroup("splatbench", "splatbench: conformance and regression checks of a 3DGS rasterizer")
    group.addoption("--splatbench-backend", dest="splatbench_backend", default=None, metavar="MODULE:CALLABLE",
                    help="Run conform's probes on this backend as test items (a built-in name, an entry point, "
                         "or module:function).")
    group.addoption("--splatbench-against", dest="splatbench_against", default=None, metavar="DIR",
                    help="Also check it against this snapshot (`splatbench snapshot`): one item per quantity.")
    group.addoption("--splatbench-device", dest="splatbench_device", default="auto", metavar="cpu|cuda|auto",
                    help="Where the backend's inputs live (default: auto).")


class _State:
    """What the plugin loaded and computed, once per session."""

    def __init__(self, spec: str, against: str | None, device: str):
        from splatbench.backends.registry import get_backend
        from splatbench.errors import SplatbenchError

        self.spec, self.against, self.device = spec, against, device
        from splatbench.verification.calls import Fault, check_signature

        try:
            self.backend = get_backend(spec, command="pytest")
            try:  # a spec that cannot take conform's call is wired up wrong: once here, not per item
                check_signature(self.backend)
            except Fault as fault:
                raise pytest.UsageError(f"splatbench: --splatbench-backend {spec}: {fault}") from None
            self.snapshot = None
            if against:
                from splatbench.regress.files import read_snapshot

                self.snapshot = read_snapshot(against)
                self.snapshot.verify()  # every file's SHA-256 and arrays, once, not per item
        except SplatbenchError as exc:
            raise pytest.UsageError(f"splatbench: {exc}") from None
        self._conform = None
        self._check = None

    def conform(self):
        if self._conform is None:
            from splatbench.conform import conform

            self._conform = conform(self.backend, device=self.device)
        return self._conform

    def check(self):
        if self._check is None:
            from splatbench.regress.against_snapshot import check

            self._check = check(self.backend, self.against, device=self.device, diagnose=False)
        return self._check


def pytest_configure(config) -> None:
    spec = config.getoption("splatbench_backend", default=None)
    if spec:
        setattr(config, _STATE_KEY, _State(spec, config.getoption("splatbench_against"),
                                           config.getoption("splatbench_device")))
    elif config.getoption("splatbench_against", default=None):
        raise pytest.UsageError("splatbench: --splatbench-against needs --splatbench-backend")


class SplatbenchFailure(Exception):
    """One item's failure: a single line, shown without a traceback."""


class _Item(pytest.Item):
    def __init__(self, *, state, kind: str, key, **kwargs):
        super().__init__(**kwargs)
        self.state, self.kind, self.key = state, kind, key

    def runtest(self) -> None:
        if self.kind == "conform":
            _run_probe(self.state, self.key)
        else:
            _run_quantity(self.state, self.key)

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, SplatbenchFailure):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, self.nodeid.rsplit("/", 1)[-1]  # the failure's heading: splatbench::...


class _Group(pytest.Collector):
    """A node of the plugin's tree (``splatbench``, ``splatbench::conform``, ``splatbench::check``,
    ``splatbench::check::SCENE``); ``children(self)`` makes its nodes."""

    def __init__(self, *, children, **kwargs):
        super().__init__(**kwargs)
        self._children = children

    def collect(self):
        return self._children(self)

    def reportinfo(self):
        return self.path, None, self.nodeid


def _run_probe(state: _State, name: str) -> None:
    report = state.conform()
    r = next(r for r in report.results if r.name == name)
    if r.status == "skip":
        pytest.skip(r.detail)
    if r.status == "explained":
        d = next((d for d in report.diagnosis if name in d.explains), None)
        why = f"{d.axis} is {d.found!r}, not the declared {d.expected!r}" if d else r.explained_by
        raise SplatbenchFailure(f"{name}: fails under the declared conventions; conform's diagnosis: {why}")
    if r.status == "fail":
        raise SplatbenchFailure(f"{name}: {_root(report, name)} (measured: {r.detail})")


def _root(report, name: str) -> str:
    """Conform's one-line root cause of a failing probe: its own defect, or the defect it follows from."""
    for d in report.defects:
        if d.probe == name:
            return d.cause
        if name in d.follows:
            return f"follows from {d.probe}: {d.cause}"
    r = next(r for r in report.results if r.name == name)
    return r.cause or "fails"


def _run_quantity(state: _State, key: tuple[str, str] | None) -> None:
    report = state.check()
    if key is None:  # the declaration: a changed one fails as check does (exit 1), even with no quantity moved
        if report.declared_changes:
            raise SplatbenchFailure(f"the declared conventions changed since the snapshot: "
                                    f"{', '.join(report.declared_changes)}; take the snapshot again if that is intended")
        return
    r = next((r for r in report.results if (r.scene, r.quantity) == key), None)
    if r is None:
        raise SplatbenchFailure(f"{key[0]}::{key[1]}: not measured")
    if not r.passed:
        line = r.line()
        if r.difference is not None:
            conform = state.conform()
            if conform.diagnosis or conform.defects:
                first = conform.diagnosis[0] if conform.diagnosis else None
                line += (f"; conform: {first.axis} is {first.found!r}, not the declared {first.expected!r}" if first
                         else f"; conform: defect {conform.defects[0].probe}: {conform.defects[0].cause}")
        raise SplatbenchFailure(line)


@pytest.hookimpl(tryfirst=True)  # before -k / -m deselect, so that they select among these items too
def pytest_collection_modifyitems(session, config, items) -> None:
    """The plugin's tree, collected as pytest collects files (each node reported, so that the terminal
    and ``--collect-only`` count its items), appended to ``items``."""
    state = getattr(config, _STATE_KEY, None)
    if state is None:
        return
    from splatbench.conform.probes import PROBES

    def item(parent, name, kind, key):
        return _Item.from_parent(parent, name=name, state=state, kind=kind, key=key)

    def group(parent, name, children):
        return _Group.from_parent(parent, name=name, children=children)

    def conform(node):
        return [item(node, p.name, "conform", p.name) for p in PROBES]

    def scene(rec):
        return lambda node: [item(node, q, "check", (rec["name"], q)) for q in rec["quantities"]]

    def check(node):
        return [item(node, "declared_conventions", "check", None)] + [
            group(node, rec["name"], scene(rec)) for rec in state.snapshot.manifest["scenes"]]

    def root(node):
        return [group(node, "conform", conform)] + ([group(node, "check", check)] if state.snapshot else [])

    top = _Group.from_parent(session, name="splatbench", nodeid=_root_id(config), path=session.path, children=root)
    items.extend(session.genitems(top))


def _root_id(config) -> str:
    """The tree's node id: ``splatbench``, under the folder pytest runs in when that is below the
    rootdir (node ids are relative to the rootdir, and pytest shows them relative to that folder:
    ``splatbench::...``, never ``..::splatbench``)."""
    here, root = config.invocation_params.dir, config.rootpath
    try:
        below = here.relative_to(root).as_posix()
    except ValueError:
        below = "."
    return "splatbench" if below == "." else f"{below}/splatbench"


@pytest.fixture
def splatbench_scene(request):
    """A function checking one of the project's own scenes against the float64 oracle (module doc)."""

    def check_scene(means, log_scales, quats, opacity_logits, sh, camera, *, backend=None, sh_degree=None,
                    background=None) -> None:
        __tracebackhide__ = True  # a failure is its one line, not this function's source and the arrays
        from splatbench.verification.calls import Fault
        from splatbench.errors import SplatbenchError

        state = getattr(request.config, _STATE_KEY, None)
        if backend is None and state is None:
            pytest.skip("no backend: give --splatbench-backend or splatbench_scene(..., backend=...)")
        try:
            failure = _scene_failure(means, log_scales, quats, opacity_logits, sh, camera, sh_degree, background,
                                     state.backend if backend is None else backend)
        except (SplatbenchError, Fault) as exc:
            failure = f"splatbench_scene: {exc}"
        if failure:
            pytest.fail(failure, pytrace=False)

    return check_scene


def _scene_failure(means, log_scales, quats, opacity_logits, sh, camera, sh_degree, background, backend) -> str:
    """What `splatbench_scene` finds wrong, in one line ("" when nothing)."""
    import numpy as np

    from splatbench.backends.registry import get_backend
    from splatbench.verification.bounds import BAND_BUDGET, gradient_bound
    from splatbench.regress.measure import (GRAD_PREFIX, bands, gradient_difference, oracle, oracle_gradients,
                                            output_excess, render)
    from splatbench.regress.snapshot_scenes import Scene

    b = get_backend(backend, command="pytest") if isinstance(backend, str) else get_backend(backend)
    f64 = lambda x: np.asarray(np.asarray(x.detach().cpu() if hasattr(x, "detach") else x,  # noqa: E731
                                          dtype=np.float32), dtype=np.float64)
    scene = Scene(f64(means), f64(log_scales), f64(quats), f64(opacity_logits), f64(sh), camera,
                  None if background is None else tuple(float(v) for v in background), sh_degree, name="user")
    got = render(b, scene, "cpu")
    band = bands(b.info, scene)
    ref = oracle(b.info, scene, band=False)
    z_max = max(1.0, float(np.abs(ref.depth).max(initial=0.0)))
    for q, want in (("rgb", ref.rgb), ("alpha", ref.alpha), ("depth", ref.depth)):
        if q in got:
            excess = output_excess(q, got[q], want, got.get("alpha"), ref.alpha, z_max, band)
            if excess > 1:
                return (f"{b.name}: {q}: {excess:.3g} x the float32 bound away from the oracle outside the "
                        f"boundary band ({int(band.band.sum())} pixels)")
    grads = oracle_gradients(b.info, scene, got.get("alpha"))
    if grads is None or not any(q.startswith(GRAD_PREFIX) for q in got):
        return ""
    bound = gradient_bound(camera.width * camera.height, 0, band.grad_weight)
    for q in (q for q in got if q.startswith(GRAD_PREFIX)):
        rest, in_band, where = gradient_difference(q, got[q], grads[q], band, grads)
        if rest > bound or in_band > BAND_BUDGET:
            return (f"{b.name}: {q}: relative L2 {rest:.2e} against the oracle outside the gradient band "
                    f"({int(band.grad_band.sum())} Gaussians), bound {bound:.1e}; largest at {where}")
    return ""
