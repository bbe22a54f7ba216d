"""The compiled kernel in its two forms, and which one a piece of work runs.

Every kernel function is written once, as plain Python over arrays and scalars, and marked
`jit`. The *interpreted* form is the modules themselves: importing them imports numpy and
nothing else. The *compiled* form is built on demand: each marked function is handed to numba
(``cache=True``) with its global names rebound to the compiled functions and modules, so the
compiled code calls compiled code. The two forms give the same numbers bit for bit (no
fast-math; tests/test_jit.py checks every entry point), so a run can change form between two
periods and a result never depends on which form computed it.

Which form runs (`kernel`), from ``CRAWLSIM_KERNEL``:

* ``auto`` (the default): interpreted first. A compiled period is about 60 times faster, but
  loading the compiled form from numba's cache costs about 0.3 s (importing numba, reading the
  machine code) and compiling it costs about a minute of CPU. So work runs interpreted until it
  has taken `SWITCH_SECONDS`; then, if the compiled form is in the cache (a stamp written when
  it was complete, `ready`), it is loaded and the work goes on compiled. If it is not, a
  background process compiles it (``crawlsim warmup``, one core, at low priority; at most one
  per cache) while the work goes on interpreted, and switches when the stamp appears. A small
  answer never waits for numba, and a long job runs interpreted only until the compile is done.
* ``compiled``: the compiled form from the start (compiling in the foreground if needed, with
  one line on stderr when numba really starts compiling).
* ``python``: the interpreted form only (as ``NUMBA_DISABLE_JIT=1``, which numba itself reads).

``CRAWLSIM_BACKGROUND_COMPILE=0`` keeps ``auto`` from starting a background compile.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import sys
import time
import types
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

#: The kernel's modules, callees before callers.
MODULES = (
    "policy",
    "chain",
    "piece",
    "sampling",
    "events",
    "terrain",
    "eventloop",
    "jacobian",
    "tangent",
    "tangent_catchup",
    "implicit",
)
#: Seconds of interpreted work after which loading the compiled form pays (its load time).
SWITCH_SECONDS = 0.3
#: What `crawlsim warmup` takes with an empty cache on one core of a 2-core machine (median
#: of 3 runs, docs/benchmarks.md): the estimate printed when a compile starts.
COMPILE_SECONDS = 60

_marked: dict[str, dict[str, types.FunctionType]] = {}


def jit(fn: F) -> F:
    """Mark a kernel function: interpreted as it is, compiled by numba in the compiled form."""
    _marked.setdefault(fn.__module__, {})[fn.__name__] = fn  # type: ignore[assignment]
    return fn


class Form(StrEnum):
    AUTO = "auto"
    COMPILED = "compiled"
    PYTHON = "python"


class World:
    """The kernel's modules in one form: ``world.chain.catch_up(...)``."""

    def __init__(self, compiled: bool, modules: dict[str, types.ModuleType] | None = None):
        self.compiled = compiled
        self._modules = modules or {}

    def __getattr__(self, name: str) -> Any:
        if name not in MODULES:
            raise AttributeError(name)
        module = self._modules.get(name)
        if module is None:
            module = self._modules[name] = importlib.import_module(f"crawlsim.kernel.{name}")
        return module


INTERPRETED = World(False)
_compiled: World | None = None
_state: dict[str, Any] = {"started": None, "background": None, "announced": False, "depth": 0, "compiling": None}


def form() -> Form:
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return Form.PYTHON
    value = os.environ.get("CRAWLSIM_KERNEL", "auto").strip().lower()
    try:
        return Form(value)
    except ValueError:
        return Form.AUTO


@contextmanager
def forced(chosen: Form | str) -> Iterator[None]:
    """Run the enclosed work in one form (tests, `crawlsim.study.warmup`)."""
    old = os.environ.get("CRAWLSIM_KERNEL")
    os.environ["CRAWLSIM_KERNEL"] = str(Form(chosen))
    try:
        yield
    finally:
        if old is None:
            del os.environ["CRAWLSIM_KERNEL"]
        else:
            os.environ["CRAWLSIM_KERNEL"] = old


def kernel() -> World:
    """The form the next piece of work (a period, a walk, a sweep point) runs in."""
    chosen = form()
    if chosen is Form.PYTHON:
        return INTERPRETED
    if chosen is Form.COMPILED or _compiled is not None:
        return compiled()
    now = time.perf_counter()
    if _state["started"] is None:
        _state["started"] = now
        return INTERPRETED
    if now - _state["started"] < SWITCH_SECONDS:
        return INTERPRETED
    if ready():
        return compiled()
    _background()
    return INTERPRETED


def compiled() -> World:
    """The compiled form, built once per process (numba loads each function from its cache,
    or compiles it)."""
    global _compiled
    if _compiled is None:
        import numba
        from numba.core import event

        class Announce(event.Listener):
            on_start = on_end = staticmethod(_announce)

        event.register("numba:compile", Announce())  # type: ignore[no-untyped-call,unused-ignore]
        modules = {name: importlib.import_module(f"crawlsim.kernel.{name}") for name in MODULES}
        proxies = {f"crawlsim.kernel.{name}": types.ModuleType(f"crawlsim.kernel.{name}") for name in MODULES}
        namespaces = {name: dict(module.__dict__) for name, module in modules.items()}
        dispatchers: dict[int, Any] = {}
        for name, module in modules.items():
            for fn in _marked.get(module.__name__, {}).values():
                rebound = types.FunctionType(
                    fn.__code__, namespaces[name], fn.__name__, fn.__defaults__, fn.__closure__
                )
                rebound.__qualname__, rebound.__module__ = fn.__qualname__, fn.__module__
                rebound.__kwdefaults__, rebound.__doc__ = fn.__kwdefaults__, fn.__doc__
                dispatchers[id(fn)] = numba.njit(cache=True)(rebound)
        for name, namespace in namespaces.items():
            for key, value in namespace.items():
                if isinstance(value, types.FunctionType) and id(value) in dispatchers:
                    namespace[key] = dispatchers[id(value)]
                elif isinstance(value, types.ModuleType) and value.__name__ in proxies:
                    namespace[key] = proxies[value.__name__]
            proxies[f"crawlsim.kernel.{name}"].__dict__.update(namespace)
        _compiled = World(True, {name: proxies[f"crawlsim.kernel.{name}"] for name in MODULES})
    return _compiled


def _announce(ev: Any) -> None:
    """Note when numba compiles a kernel function (a cache hit compiles nothing), and say so on
    stderr the first time in this process."""
    if not getattr(ev.data["dispatcher"].py_func, "__module__", "").startswith("crawlsim.kernel."):
        return
    _state["depth"] += 1 if ev.is_start else -1
    if ev.is_start and _state["depth"] == 1:
        _state["compiling"] = time.perf_counter()
        if not _state["announced"]:
            _state["announced"] = True
            print(
                f"crawlsim: compiling the kernel, about {COMPILE_SECONDS} s once "
                "(`crawlsim warmup` compiles it on every core)",
                file=sys.stderr,
                flush=True,
            )
    elif _state["depth"] == 0:
        _state["compiling"] = None


def compiling() -> str:
    """A note for progress lines while numba compiles the kernel in this process, else ''."""
    since = _state.get("compiling")
    if since is None:
        return ""
    return f"compiling the kernel ({time.perf_counter() - since:.0f} s of about {COMPILE_SECONDS} s, once)"


def source_key() -> str:
    """What the compiled form depends on: the kernel's sources, numba's and Python's versions."""
    from importlib.metadata import version

    digest = hashlib.sha256(f"{version('numba')} {sys.version}".encode())
    for name in MODULES + ("jit",):
        digest.update(Path(__file__).with_name(f"{name}.py").read_bytes())
    return digest.hexdigest()[:16]


def cache_dir() -> Path:
    """Where numba keeps the compiled form (``NUMBA_CACHE_DIR``, else beside the sources when
    they are writable, else the user's cache), and the stamp with it."""
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured:
        return Path(configured)
    here = Path(__file__).parent / "__pycache__"
    if os.access(here if here.exists() else here.parent, os.W_OK):
        return here
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "crawlsim"


def stamp() -> Path:
    return cache_dir() / f"crawlsim-kernel-{source_key()}.ready"


def ready() -> bool:
    """Whether the compiled form of these sources was completed in the cache."""
    return stamp().exists()


def this_python(*args: str) -> tuple[list[str], dict[str, str]]:
    """``python -P ARGS`` and an environment whose ``PYTHONPATH`` starts with the folder this
    crawlsim was imported from, so that a subprocess (warmup's tasks, the background compile)
    imports these very sources: neither a checkout's ``crawlsim/`` in its working directory
    (``-m`` puts that first) nor an installed copy that this one shadows. numba's cache and the
    stamp are per source path."""
    root = str(Path(os.path.abspath(__file__)).parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return [sys.executable, "-P", *args], env


def _background() -> None:
    """Start ``crawlsim warmup --background`` (of this crawlsim, `this_python`) once per
    process; it compiles unless another one holds the cache's lock, and writes the stamp when
    done."""
    if _state["background"] is not None or os.environ.get("CRAWLSIM_BACKGROUND_COMPILE", "1") == "0":
        return
    import subprocess

    argv, env = this_python("-m", "crawlsim", "warmup", "--background")
    _state["background"] = subprocess.Popen(
        argv,
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
