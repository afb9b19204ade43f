"""onnxruntime wrappers: one session per model file, and load-time fused graphs.

``onnx`` is imported only inside :class:`Fused` (graph composition at load time); without
it (``pip install .[service]`` does not bring it) a fused graph runs as its three
sessions in sequence, with the same results.
"""

from __future__ import annotations

import functools
import hashlib
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import numpy.typing as npt
import onnxruntime as ort

from core.manifest import ManifestError, ModelEntry

if TYPE_CHECKING:  # pragma: no cover
    import onnx

T = TypeVar("T")

#: Rows per onnxruntime run: more rows run as blocks of this many, one run each, so that
#: the networks' activations stay in the CPU's cache (a 4,096-edit 2-target batch in
#: process: 16-19k -> 24-30k poses/s, block sizes 64-1,024 alike; onnxruntime alone, the
#: fused graph on 8,192 rows: 80k rows/s in one run, 112k in blocks of 256). A row's
#: answer does not depend on its block: bit-identical (tests/service/test_runtime.py).
ROW_BLOCK = 256


def session_options(threads: int = 1) -> ort.SessionOptions:
    """Sequential, single inter-op thread, full graph optimisation, quiet."""
    if hasattr(ort, "disable_telemetry_events"):  # no usage reporting from a server
        ort.disable_telemetry_events()
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.log_severity_level = 3
    return options


#: A network's bound run (:meth:`_FewRows.bound`): its input buffers, its output, the run.
Bound = tuple[list[npt.NDArray[np.float32]], npt.NDArray[np.float32], Callable[[], None]]

#: Runs of at most this many rows go through :class:`_FewRows` by ``__call__`` (an edit
#: alone, and its mirror image as a second row): the hot path's runs. Callers that bind
#: their own buffers (``service.lean.solve_one``, ``service.completion``'s critic) bind
#: more: up to ``service.lean.BOUND_ITEMS`` items, each and its mirror image, a lone turn
#: search's candidates; each row count a network is run with keeps its bound buffers per
#: thread (a few kB), on the network's shared session past ``OWN_ROWS``.
FEW_ROWS = 4
#: Runs of at most this many rows may take a session of their own (:class:`_FewRows`).
OWN_ROWS = 2


class _FewRows:
    """Runs of a few rows through an I/O binding with buffers bound once per thread and
    shape: the inputs are copied into the bound arrays and the output read from its bound
    array, which saves onnxruntime's per-call feed conversion and output allocation
    (measured 30 vs 36 us per fused call; rebinding per call was slower than ``run``).
    Results are bit-identical to ``session.run``.

    With ``make`` (a new session of the same graph), each shape runs on a session of its
    own, the one it was first run with: onnxruntime runs a session's first input shape
    fastest, every later shape 3-4 us slower a run (the 2-target fused graph on one row:
    20.9 us run first, 24.9 after two rows; two rows 25.0 first, 27.7 after one; a /tmp
    script, same bits), so a batch's blocks or another row count run first no longer slow
    the edit's runs. The first shape takes the network's own session where nothing has run
    on it yet (``used``); a later one of at most ``OWN_ROWS`` rows (a lone edit, and it with
    its mirror image) a session made on first use (~2 ms, ~1.7 MB for a fused graph) by
    ``make``, from the graph's file read again and checked against the manifest's sha256;
    where the file no longer holds those bytes (changed or removed under a running server:
    it gave a 500 or another network's answers, a review) ``make`` gives None and the shape
    runs on the shared session, the same answers. The bytes are not kept from load for
    it (with onnxruntime's own reference, :func:`_session`, ~27 MiB of a worker's RSS).
    3 and 4 rows run on the shared session, so a network holds at most two sessions (the
    worst case was four: +125 MB an engine, a review's measurement)."""

    def __init__(
        self, session: ort.InferenceSession, inputs: list[str], output: str,
        make: Callable[[], ort.InferenceSession | None] | None = None,
    ) -> None:  # fmt: skip
        self.session, self.inputs, self.output, self.make = session, inputs, output, make
        self.local = threading.local()
        self.sessions: dict[tuple[tuple[int, ...], ...], ort.InferenceSession] = {}
        self.lock = threading.Lock()
        #: whether the shared session has run (a shape of its own, or a batch's blocks)
        self.used = False

    def session_for(self, shapes: tuple[tuple[int, ...], ...]) -> ort.InferenceSession:
        """The session runs of ``shapes`` run on: its own with ``make`` (the shared one if
        it has not run yet), else the shared."""
        if self.make is None:
            return self.session
        with self.lock:  # one per shape, whichever thread asks first
            session = self.sessions.get(shapes)
            if session is None:
                own = not self.used or shapes[0][0] > OWN_ROWS
                made = None if own else self.make()
                session = self.session if made is None else made
                self.sessions[shapes], self.used = session, True
        return session

    def __call__(self, arrays: tuple[npt.NDArray[np.float32], ...]) -> npt.NDArray[np.float32]:
        shapes = tuple([a.shape for a in arrays])  # (a list first: a generator costs more)
        bufs, out, run = self.bound(shapes)
        for buf, a in zip(bufs, arrays, strict=True):
            np.copyto(buf, a)
        run()
        result: npt.NDArray[np.float32] = out.copy()
        return result

    def bound(self, shapes: tuple[tuple[int, ...], ...]) -> Bound:
        """This thread's bound buffers for inputs of ``shapes``: the inputs (written in
        place by the caller, as ``service.lean.solve_one``'s kernels do), the output
        (overwritten by the next run) and the run."""
        states = getattr(self.local, "states", None)
        if states is None:
            states = self.local.states = {}
        state: Bound | None = states.get(shapes)
        if state is None:  # a few shapes per network (rows 1 to FEW_ROWS; bound: more)
            zeros = {
                n: np.zeros(s, dtype=np.float32) for n, s in zip(self.inputs, shapes, strict=True)
            }
            session = self.session_for(shapes)
            first = session.run([self.output], zeros)
            bufs = [np.empty(s, dtype=np.float32) for s in shapes]
            out = np.empty(first[0].shape, dtype=np.float32)
            io = session.io_binding()
            for name, buf in zip(self.inputs, bufs, strict=True):
                io.bind_ortvalue_input(name, ort.OrtValue.ortvalue_from_numpy(buf))
            io.bind_ortvalue_output(self.output, ort.OrtValue.ortvalue_from_numpy(out))
            state = states[shapes] = (bufs, out, _runner(session, io))
        return state


def _runner(session: ort.InferenceSession, io: ort.IOBinding) -> Callable[[], None]:
    """The bound run. The public ``run_with_iobinding`` first checks for WebGPU graph
    capture (a few us per call, a third of a batch-of-one network run's overhead); a CPU
    session never captures, so where the onnxruntime build exposes its binding objects we
    call the session's own run directly: the same computation."""
    sess, bound = getattr(session, "_sess", None), getattr(io, "_iobinding", None)
    if sess is None or bound is None or not hasattr(sess, "run_with_iobinding"):
        return lambda: session.run_with_iobinding(io)
    return functools.partial(sess.run_with_iobinding, bound, None)


def _loaded(make: Callable[[], T], path: Path, entry: ModelEntry, how: str = "") -> T:
    """``make()``, a model file's session or graph; what it raises (a corrupt file whose
    manifest entry matches, as after a re-export or with the manifest made anew: protobuf
    parsing failed) as a :class:`ManifestError` naming the file and its entry. onnxruntime's
    message named neither, so the ready route and the ``models_not_ready`` line did not say
    which of some 40 files was bad (an ops audit)."""
    try:
        return make()
    except Exception as exc:
        what = f"model {entry.name!r}{f' ({how})' if how else ''}"
        raise ManifestError(path, f"{what}: cannot be loaded: {exc}") from exc


def _session(data: bytes, options: ort.SessionOptions) -> ort.InferenceSession:
    """A CPU session of the graph ``data``, which it does not keep. onnxruntime's Python
    session holds the bytes it is made from for as long as it lives (``_model_bytes``, to
    make itself anew if a provider fails and it falls back; 1.32's own comment: "This is bad
    as we're holding the memory indefinitely"): every network's file, ~27 MiB of a worker's
    RSS from load on, and a copy more for each few-rows shape's own session. A CPU session
    has no provider to fall back to, so its fallback is disabled and that reference
    dropped (where a later onnxruntime no longer holds it, nothing to drop)."""
    session = ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    session.disable_fallback()
    if getattr(session, "_model_bytes", None) is data:
        session._model_bytes = None
    return session


def _session_if_unchanged(
    path: Path, entry: ModelEntry, options: ort.SessionOptions
) -> ort.InferenceSession | None:
    """A new session of ``entry``'s network from its file read again, or None where the
    file cannot be read or no longer holds the bytes the manifest names (sha256): then
    the caller runs on the session it has, the verified network's."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if hashlib.sha256(data).hexdigest() != entry.sha256:
        return None
    return _session(data, options)


class Net:
    """One onnxruntime session with a single input/output signature."""

    def __init__(
        self, path: Path, entry: ModelEntry, options: ort.SessionOptions, block: int = ROW_BLOCK
    ) -> None:
        self.entry, self.block = entry, block
        data = path.read_bytes()  # read once, checked: the session is made from these bytes
        if hashlib.sha256(data).hexdigest() != entry.sha256:
            raise ManifestError(path, "sha256 does not match the manifest (changed since read)")
        self.session = _loaded(functools.partial(_session, data, options), path, entry)
        self.inputs = [i.name for i in entry.inputs]
        self.output = entry.outputs[0].name
        got = [i.name for i in self.session.get_inputs()]
        if got != self.inputs:
            raise ValueError(f"{path.name}: graph inputs {got}, manifest says {self.inputs}")
        # the bytes are not kept (~27 MiB for all the networks): a few-rows shape's own
        # session reads the file again, and checks it
        make = functools.partial(_session_if_unchanged, path, entry, options)
        self.few = _FewRows(self.session, self.inputs, self.output, make)

    def __call__(self, *arrays: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        if arrays[0].shape[0] <= FEW_ROWS:
            return self.few(arrays)
        self.few.used = True  # (its first shape is no few-rows shape's now)
        return blocked(self.session, self.inputs, self.output, arrays, self.block)


class Fused:
    """encoder -> one solver -> decoder as ONE graph (``pose, targets -> pose``), composed
    at load time from the verified files: a single-solver edit costs one onnxruntime run
    instead of three, with bit-identical results."""

    def __init__(
        self, enc: ModelEntry, solver: ModelEntry, dec: ModelEntry, models_dir: Path,
        options: ort.SessionOptions,
    ) -> None:  # fmt: skip
        self.chain: tuple[Net, Net, Net] | None = None
        try:
            import onnx  # only here: composing graphs is a load-time job
            import onnx.compose
        except ImportError:  # a slim install: the same three runs, one after the other
            self.chain = (
                Net(models_dir / enc.file, enc, options),
                Net(models_dir / solver.file, solver, options),
                Net(models_dir / dec.file, dec, options),
            )
            return

        def load(entry: ModelEntry, prefix: str) -> onnx.ModelProto:
            path = models_dir / entry.file
            graph = _loaded(lambda: onnx.load(str(path)), path, entry)
            return onnx.compose.add_prefix(graph, prefix)

        first = onnx.compose.merge_models(
            load(enc, "e_"), load(solver, "s_"),
            io_map=[(f"e_{enc.outputs[0].name}", f"s_{solver.inputs[0].name}")],
        )  # fmt: skip
        graph = onnx.compose.merge_models(
            first, load(dec, "d_"),
            io_map=[(f"s_{solver.outputs[0].name}", f"d_{dec.inputs[0].name}")],
        )  # fmt: skip
        data = graph.SerializeToString()

        def make() -> ort.InferenceSession:  # (``data`` kept here: no file holds it)
            return _session(data, options)

        self.session = _loaded(make, models_dir / solver.file, solver, "composed with "
                               f"{enc.file} and {dec.file}")  # fmt: skip
        self.inputs = [f"e_{enc.inputs[0].name}", f"s_{solver.inputs[1].name}"]
        self.output = f"d_{dec.outputs[0].name}"
        self.few = _FewRows(self.session, self.inputs, self.output, make)

    def __call__(
        self, pose: npt.NDArray[np.float32], targets: npt.NDArray[np.float32]
    ) -> npt.NDArray[np.float32]:
        if self.chain is not None:
            encode, solve, decode = self.chain
            return decode(solve(encode(pose), targets))
        if pose.shape[0] <= FEW_ROWS:
            return self.few((pose, targets))
        self.few.used = True
        return blocked(self.session, self.inputs, self.output, (pose, targets))


def blocked(
    session: ort.InferenceSession,
    inputs: list[str],
    output: str,
    arrays: tuple[npt.NDArray[np.float32], ...],
    block: int = ROW_BLOCK,
) -> npt.NDArray[np.float32]:
    """``session``'s ``output`` for ``arrays`` (fed to ``inputs``), in runs of at most
    ``block`` rows."""

    def run(parts: tuple[npt.NDArray[np.float32], ...]) -> npt.NDArray[np.float32]:
        out: npt.NDArray[np.float32] = session.run([output], dict(zip(inputs, parts, strict=True)))[
            0
        ]
        return out

    n = arrays[0].shape[0]
    if n <= block:  # one run, as the hot path's few rows always are
        return run(arrays)
    return np.concatenate(
        [run(tuple(a[s : s + block] for a in arrays)) for s in range(0, n, block)]
    )
