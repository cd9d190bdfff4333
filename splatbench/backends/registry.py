"""Find a backend by name: built-ins, installed entry points, or ``module:function``.

    get_backend("drjit")                # a built-in
    get_backend("mypkg")                # an entry point in group "splatbench.backends"
    get_backend("mypkg.rast:render")    # user code: a Backend, or a callable
    get_backend("splatbench.backends.builtins.drjit_backend:make_drjit_backend")   # a factory, called
    as_backend(my_function)             # wrap a callable (graphdeco conventions, nothing declared)

A callable may carry its metadata as an attribute ``backend_info`` (a `BackendInfo`).
"""

from __future__ import annotations

import importlib
import inspect
from importlib import metadata

from splatbench.backends.base import Backend, BackendInfo
from splatbench.errors import InputError

ENTRY_POINT_GROUP = "splatbench.backends"

# name -> "module:attribute" of a zero-argument factory returning a Backend (loaded lazily,
# so that listing backends imports neither torch, Dr.Jit, gsplat nor Mitsuba).
_B = "splatbench.backends.builtins."
BUILTINS: dict[str, str] = {
    "drjit": _B + "drjit_backend:make_drjit_backend",
    "reference": _B + "reference_backend:make_reference_backend",
    "reference-exact": _B + "reference_backend:make_reference_exact_backend",
    "torch": _B + "torch_backend:make_torch_backend",
    "torch64": _B + "torch_backend:make_torch64_backend",
    "gsplat": _B + "gsplat_backend:make_gsplat_backend",
    "mitsuba": _B + "mitsuba_backend:make_mitsuba_backend",
}


def register_builtin(name: str, target: str) -> None:
    BUILTINS[name] = target


def available() -> list[str]:
    """Names of the built-in and installed (entry point) backends."""
    names = set(BUILTINS)
    names.update(ep.name for ep in metadata.entry_points(group=ENTRY_POINT_GROUP))
    return sorted(names)


def as_backend(obj, name: str | None = None) -> Backend:
    """A `Backend` from a Backend, a factory's result, or a plain callable."""
    if isinstance(obj, Backend):
        return obj
    if not callable(obj):
        raise InputError(f"backend: {name or obj!r} is not callable (expected a Backend or a function)")
    info = getattr(obj, "backend_info", None)
    if info is None:
        label = name or getattr(obj, "__qualname__", None) or repr(obj)
        info = BackendInfo(name=label, description="user callable; graphdeco conventions, nothing declared")
    elif not isinstance(info, BackendInfo):
        raise InputError(f"backend: {name or obj!r}.backend_info must be a splatbench.backends.BackendInfo")
    return Backend(obj, info)


# How the folder of a ``module:function`` spec gets on the path, per command that loads it.
_PATH_HINTS = {
    "splatbench": "the folder holding it must be on PYTHONPATH (the current folder is not on the splatbench "
                  "command's path): PYTHONPATH=/path/to/folder splatbench ...",
    "pytest": "the folder holding it must be on pytest's path: pythonpath = [\"/path/to/folder\"] in the pytest "
              "configuration ([tool.pytest.ini_options]), or PYTHONPATH=/path/to/folder pytest ..., or python -m "
              "pytest run from that folder",
}


def _load(target: str, label: str, command: str = "splatbench"):
    module_name, _, attr = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        hint = ""
        if isinstance(exc, ModuleNotFoundError) and exc.name and module_name.startswith(exc.name):
            hint = f"; {_PATH_HINTS[command]}"
        raise InputError(f"backend: cannot import module {module_name!r} for {label!r} ({exc}){hint}") from None
    except Exception as exc:  # noqa: BLE001 - user code failing on import is bad input, named in one line
        where = ""
        if isinstance(exc, SyntaxError) and exc.filename:
            where = f" at {exc.filename}:{exc.lineno}"
        raise InputError(f"backend: importing module {module_name!r} for {label!r} failed{where}: "
                         f"{type(exc).__name__}: {exc}") from None
    obj = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise InputError(f"backend: module {module_name!r} has no attribute {attr!r}") from None
    return obj


def get_backend(spec, *, command: str = "splatbench") -> Backend:
    """Resolve ``spec`` (a name, ``module:function``, a Backend or a callable) to a `Backend`. ``command``:
    what loads it ("splatbench" or "pytest"), for the hint of a module that is not on the path."""
    if not isinstance(spec, str):
        return as_backend(spec)
    if spec in BUILTINS:
        factory = _load(BUILTINS[spec], spec)
        return factory()
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == spec:
            obj = ep.load()
            return as_backend(obj() if _is_factory(obj) else obj, spec)
    if ":" in spec:
        obj = _load(spec, spec, command)
        return as_backend(obj() if _is_factory(obj) else obj, spec)
    raise InputError(f"backend: unknown backend {spec!r} (known: {', '.join(available())}; "
                     f"or give user code as module:function)")


def _is_factory(obj) -> bool:
    """An entry point or ``module:callable`` may name a factory callable without arguments, returning
    a `Backend`: marked ``splatbench_backend_factory = True``, or annotated ``-> Backend`` (as the
    built-ins' ``make_*_backend`` are), so that a built-in's documented path works as its name."""
    if isinstance(obj, Backend) or not callable(obj):
        return False
    if getattr(obj, "splatbench_backend_factory", False):
        return True
    try:
        ret = inspect.signature(obj).return_annotation
    except (TypeError, ValueError):
        return False
    if isinstance(ret, str):  # `from __future__ import annotations`: the annotation's text
        return ret.rsplit(".", 1)[-1] == "Backend"
    return isinstance(ret, type) and issubclass(ret, Backend)
