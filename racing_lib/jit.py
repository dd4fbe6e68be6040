"""CasADi functions on the hot path: compiled once per generated code, called without copies.

CasADi's own ``jit`` option compiles a Function afresh in every process (1-4 s each: every test
process, notebook kernel and tuning worker paid it) under a new temporary name, so its folder
grew with every run. Here the C code CasADi generates is hashed; the shared library is built once
under that hash, kept in one folder per user, and loaded by every later process. The folder
keeps the :data:`MAX_BUILDS` most recently used builds of each name and removes older ones.
Without a C compiler (or on Windows) the callers fall back to CasADi's interpreter: the same
numbers, several times slower.

:class:`BufferedFunction` calls a Function (compiled or not) on numpy arrays it owns: a plain
call converts every input to a CasADi matrix and every output back, which cost more than the
evaluation itself for the simulated car's substep and the MPC's linearization.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    # casadi is imported where a build is made (_compile): importing this module stays cheap
    import casadi as ca

log = logging.getLogger(__name__)

#: Compiled builds kept in the cache folder for each name (one per parameter set and options; the
#: least recently used beyond this are removed).
MAX_BUILDS = 16
#: Flags of the C compiler (-O1: as fast as -O3 for this code, and compiles in a third of the time;
#: -ffp-contract=off: no fused multiply-adds, which some processors' compilers would otherwise emit,
#: so compiled code computes what CasADi's interpreter computes, to the last bit, with any
#: compiler that does not default to fast math, as gcc and clang do not; only a zero may come out
#: with the other sign, which no comparison and no later sum can tell apart).
CFLAGS = ("-O1", "-ffp-contract=off", "-fPIC", "-shared")


def compile_function(fn: ca.Function) -> ca.Function | None:
    """``fn`` compiled to machine code and loaded back, or None when no C compiler works.

    Parameters
    ----------
    fn : casadi.Function
        The function to compile; the result has the same name, inputs and outputs.

    Returns
    -------
    casadi.Function or None
        The compiled function (``casadi.external``), or None with a logged reason.
    """
    compiled = compile_functions([fn])
    return None if compiled is None else compiled[0]


def compile_functions(
    fns: Sequence[ca.Function], name: str | None = None
) -> list[ca.Function] | None:
    """Several functions compiled into one shared library (one compiler run), or None.

    Parameters
    ----------
    fns : sequence of casadi.Function
        The functions, with distinct names; each result has its function's name, inputs and
        outputs.
    name : str, optional
        The library's name in the cache folder (default: the first function's name). The cache
        keeps :data:`MAX_BUILDS` builds of each name, so give each group a name of its own.

    Returns
    -------
    list of casadi.Function or None
        The compiled functions (``casadi.external``) in the order given, or None with a logged
        reason when no C compiler works or a build cannot be loaded.
    """
    loaded, reason = _compile(fns, name or fns[0].name())
    if loaded is None:
        log.warning("compiling %s failed: %s", name or fns[0].name(), reason)
    return loaded


def compiled_or_interpreted(
    fns: Sequence[ca.Function],
    what: str,
    switch: str,
    name: str | None = None,
    finite_differences: Collection[str] = (),
) -> list[ca.Function]:
    """``fns`` compiled together, or ``fns`` themselves with one warning when that fails.

    Parameters
    ----------
    fns : sequence of casadi.Function
        The functions (see :func:`compile_functions`).
    what : str
        What they compute, for the warning: ``"the MPC linearization"``.
    switch : str
        The setting that turns compilation off, named in the warning:
        ``"MPCSettings(jit=False)"``.
    name : str, optional
        The build's name in the cache folder (default: the first function's name).
    finite_differences : collection of str
        Names of the functions whose compiled form CasADi may differentiate by finite
        differences. Compiled code has no derivatives of its own, and a graph that contains it
        cannot be differentiated otherwise: give the names of functions that sit in a graph
        CasADi differentiates as it is built (an NLP's constraints, whose derivatives the solver
        is given ready-made), never of ones whose derivatives are used.

    Returns
    -------
    list of casadi.Function
        Compiled where a C compiler works; otherwise the same functions, evaluated by CasADi's
        interpreter (the same numbers, several times slower).
    """
    loaded, reason = _compile(fns, name or fns[0].name(), finite_differences)
    if loaded is not None:
        return loaded
    log.warning(
        "compiling %s failed (%s); using CasADi's interpreter instead (the same numbers, several "
        "times slower). Install a C compiler (cc, or name one in CC), or pass %s.",
        what,
        reason,
        switch,
    )
    return list(fns)


def fix_inputs(fn: ca.Function, values: Sequence[ca.DM]) -> ca.Function:
    """``fn`` with its last ``len(values)`` inputs fixed to ``values``, a Function of the others.

    How code compiled with data as inputs (a learned correction's, one build per layout) is
    called with one set of data.

    Parameters
    ----------
    fn : casadi.Function
        Compiled or not; its last inputs take the values.
    values : sequence of casadi.DM
        The values of those inputs, in order.

    Returns
    -------
    casadi.Function
        An MX Function with ``fn``'s name, its other inputs and all its outputs, which passes the
        values on at every call; ``fn`` itself when there are no values.
    """
    import casadi as ca

    if not values:
        return fn
    n_free = fn.n_in() - len(values)
    inputs = [ca.MX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(n_free)]
    outputs = fn(*inputs, *values)
    outputs = outputs if isinstance(outputs, list | tuple) else [outputs]
    return ca.Function(
        fn.name(),
        inputs,
        list(outputs),
        [fn.name_in(i) for i in range(n_free)],
        [fn.name_out(i) for i in range(fn.n_out())],
    )


def c_compiler() -> tuple[str | None, str]:
    """The C compiler builds are made with (``$CC``, else ``cc``) and ``""``, or None and why not.

    Returns
    -------
    compiler : str or None
        The compiler's command line, when this is a POSIX system and its program is on the PATH.
    reason : str
        Why there is no compiler (empty when there is one).
    """
    if os.name != "posix":
        return None, f"builds are made with a POSIX C compiler, and this is {sys.platform}"
    compiler = os.environ.get("CC", "").strip() or "cc"
    try:
        command = shlex.split(compiler)
    except ValueError:
        return None, f"CC={compiler!r} is not a valid command line"
    if not command or shutil.which(command[0]) is None:
        return None, f"no C compiler {compiler!r} on the PATH"
    return compiler, ""


def _compile(
    fns: Sequence[ca.Function], name: str, finite_differences: Collection[str] = ()
) -> tuple[list[ca.Function] | None, str]:
    """The compiled functions and ``""``, or None and the reason they could not be had.

    ``finite_differences``: see :func:`compiled_or_interpreted`.
    """
    import casadi as ca

    compiler, reason = c_compiler()
    if compiler is None:
        return None, reason
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for fn in fns:
        gen.add(fn)
    code = gen.dump()
    key = hashlib.sha256(
        "\n".join([code, " ".join(CFLAGS), compiler, ca.__version__]).encode("utf-8")
    ).hexdigest()[:16]
    reason = ""
    for _attempt in range(2):  # another process may prune the build between our steps: retry
        try:
            folder = Path(cache_dir())
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)  # a temp cleaner removed it
            library = folder / f"{name}_{key}.so"
            if not library.exists():
                _build(code, library, compiler)
            os.utime(library)  # most recently used: kept by the pruning below
            loaded = [
                ca.external(fn.name(), str(library), {"enable_fd": fn.name() in finite_differences})
                for fn in fns
            ]
        except FileNotFoundError as exc:
            reason = str(exc)
            continue
        except (OSError, RuntimeError, subprocess.CalledProcessError) as exc:
            # A folder mounted noexec, a compiler that fails, a damaged build: the caller falls
            # back to the interpreter.
            detail = getattr(exc, "stderr", "") or str(exc)
            return None, f"{compiler}: {detail.strip()[:300]}"
        _prune(folder, name, keep=library)
        return loaded, ""
    return None, f"{compiler}: {reason}"


def _build(code: str, library: Path, compiler: str) -> None:
    """Compile ``code`` into ``library`` atomically (a temporary name, then a rename)."""
    folder = library.parent
    fd, source = tempfile.mkstemp(prefix=".build_", suffix=".c", dir=folder)
    with os.fdopen(fd, "w") as fh:
        fh.write(code)
    partial = f"{source[:-2]}.so"
    try:
        subprocess.run(
            [*shlex.split(compiler), *CFLAGS, "-o", partial, source],
            check=True,
            capture_output=True,
            text=True,
        )
        os.replace(partial, library)
    finally:
        for leftover in (source, partial):
            if os.path.exists(leftover):
                os.unlink(leftover)


def _prune(folder: Path, name: str, keep: Path) -> None:
    """Remove the builds of ``name`` beyond :data:`MAX_BUILDS`, least recently used first.

    A build of ``name`` is ``<name>_<16 hex digits>.so``, so ``a`` never prunes ``a_b``'s builds.

    Builds in progress (``.build_*``) are never touched. A process that has a removed build
    loaded keeps using it: on POSIX a removed file stays mapped.
    """

    def used(path: Path) -> float:
        try:
            return path.stat().st_mtime
        except OSError:
            return -1.0  # removed meanwhile by another process

    pattern = re.compile(rf"{re.escape(name)}_[0-9a-f]{{16}}\.so")  # not another name's builds
    mine = [path for path in folder.glob(f"{name}_*.so") if pattern.fullmatch(path.name)]
    builds = sorted(mine, key=used, reverse=True)
    for old in builds[MAX_BUILDS:]:
        if old != keep:
            try:
                old.unlink()
            except OSError:
                pass  # another process removed it first


@functools.cache
def cache_dir() -> str:
    """The folder of compiled builds: one per user, private, reused by every process.

    If the name is taken by something that is not our own private folder, a private folder
    with a suffix is used instead (the same one by every process of this user).
    """
    path = os.path.join(tempfile.gettempdir(), f"racing_lib_jit_{os.getuid()}")
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        info = os.lstat(path)
        if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and info.st_mode & 0o077 == 0:
            return path
    except OSError:
        pass
    for k in range(1, 100):
        alt = f"{path}_{k}"
        try:
            os.makedirs(alt, mode=0o700, exist_ok=True)
            info = os.lstat(alt)
            if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid():
                if info.st_mode & 0o077 == 0:
                    return alt
        except OSError:
            continue
    return tempfile.mkdtemp(prefix="racing_lib_jit_")


class BufferedFunction:
    """A CasADi Function evaluated in place on numpy buffers.

    Each dense input and output is one flat float64 array in CasADi's column-major order (a
    matrix of r rows and c columns is the C-ordered array of shape (c, r), so an input whose
    columns are stages is written row by row). Write the inputs into :attr:`inputs`, call, and
    read :attr:`outputs`; the outputs are overwritten by the next call, so copy what you keep.

    Parameters
    ----------
    fn : casadi.Function
        A Function with dense inputs and outputs (``casadi.densify`` an output if needed).

    Notes
    -----
    A call costs 1-3 microseconds plus the evaluation, against about 15-40 for a plain call with
    its conversions (``benchmarks/bench_sim.py``, ``benchmarks/bench_mpc.py``).
    """

    def __init__(self, fn: ca.Function) -> None:
        for kind, count, sparsity in (
            ("input", fn.n_in(), fn.sparsity_in),
            ("output", fn.n_out(), fn.sparsity_out),
        ):
            for i in range(count):
                if not sparsity(i).is_dense():
                    raise ValueError(
                        f"BufferedFunction needs dense {kind}s: {kind} {i} of {fn.name()!r} is "
                        "sparse; densify it when building the Function."
                    )
        self.fn = fn
        self.inputs = [np.zeros(fn.numel_in(i)) for i in range(fn.n_in())]
        self.outputs = [np.zeros(fn.numel_out(i)) for i in range(fn.n_out())]
        self._buffer, self._evaluate = fn.buffer()
        for i, array in enumerate(self.inputs):
            self._buffer.set_arg(i, memoryview(array))
        for i, array in enumerate(self.outputs):
            self._buffer.set_res(i, memoryview(array))

    def __call__(self) -> list[np.ndarray]:
        """Evaluate on the current :attr:`inputs`; returns :attr:`outputs` (overwritten)."""
        self._evaluate()
        return self.outputs
