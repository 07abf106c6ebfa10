"""A traced network's adjoints, recorded during a render's backward pass (:class:`AdjointRecorder`),
from which the estimator computes the weights' gradient itself (``estimate.numpy_network``).

Why: Dr.Jit's own derivative of the traced network sums each weight's gradient over the lanes
inside the kernel, one horizontal sum per weight and evaluation: about half of a render's backward
pass. Recording each evaluation's input and adjoint (a handful of values) and multiplying them out
afterwards as matrix products gives the same gradient for a fraction of the time
(tests/test_adjoints.py holds the two together).

How: while recording, the network's output is ``f + p + sum_j q_j x_j`` per channel, where ``p``
and ``q`` are gathered from zero buffers at a slot of the evaluation's own (``dr.scatter_inc``):
the values do not change, and the backward pass leaves ``dL/df`` in ``p``'s gradient and ``x_j
dL/df`` in ``q_j``'s. Side effects such as a plain scatter of ``x`` would not do: Dr.Jit runs a
symbolic call's derivative as a second trace of the call, which keeps the slot's increment (its
value is used) but not stores whose results nothing reads. Each trace of the call takes a segment
of its own (one counter may be incremented once per symbolic region); only the derivative's
trace receives adjoints.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

#: The network inputs a record keeps: an isotropic network's five non-zero ones (input 1, the
#: half vector's second component, is zero: ``network.network_input``).
RECORDED_INPUTS = (0, 2, 3, 4, 5)
#: Values per record: the three output adjoints, then per channel each recorded input times that
#: channel's adjoint.
RECORD = 3 + 3 * len(RECORDED_INPUTS)


class RecorderOverflow(RuntimeError):
    """More evaluations than a segment's capacity: ``needed`` slots would have held them."""

    def __init__(self, needed: int, capacity: int):
        super().__init__(f"{needed} network evaluations in one call's trace, room for {capacity}")
        self.needed = needed


class _Segment:
    """One trace's records: a counter and the zero buffer whose gradient receives them."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.counter = dr.zeros(mi.UInt32, 1)
        self.probes = dr.zeros(mi.Float, RECORD * capacity)
        dr.enable_grad(self.probes)


class AdjointRecorder:
    """Records the adjoints of one network's evaluations between :meth:`start` and :meth:`stop`:
    attach it as ``TracedNetwork.recorder``, render with :attr:`parameters` as ``mi.render``'s
    ``params`` (so that the render runs its backward pass), backpropagate the loss, take
    :meth:`received` before :meth:`stop`, and decode it (:func:`decode_records`)."""

    def __init__(self):
        self.capacity = 0
        self._segments: list[_Segment] = []
        self._key = None

    def start(self, capacity: int) -> None:
        """Records from now on, at most ``capacity`` evaluations per trace of the network (a
        render's lanes times the evaluations per lane at one call site)."""
        self.capacity = int(capacity)
        self._segments = []
        self._key = dr.zeros(mi.Float, 1)
        dr.enable_grad(self._key)

    def stop(self) -> None:
        self.capacity, self._segments, self._key = 0, [], None

    @property
    def parameters(self) -> mi.SceneParameters:
        """What ``mi.render`` is to differentiate: nothing the scene reads, so that only the
        recorded probes receive gradients."""
        return mi.SceneParameters({"adjoint_recorder": (self._key, None, None, mi.ParamFlags.Differentiable)})

    def recording(self) -> bool:
        """Whether the current trace records: started, and gradients not suspended (a render's
        primal pass evaluates without recording)."""
        return self._key is not None and dr.grad_enabled(self._key)

    def probe(self, f: list, x: list, valid) -> list:
        """``f`` (three channels, detached) plus the zero probes of a new slot for each ``valid``
        lane; ``x`` the network input (an isotropic RGB network's)."""
        if len(f) != 3 or x[1] is not None:
            raise ValueError("adjoints are recorded for isotropic RGB networks only")
        segment = _Segment(self.capacity)
        self._segments.append(segment)
        slot = dr.scatter_inc(segment.counter, mi.UInt32(0), valid)
        keep = valid & (slot < self.capacity)
        base = slot * RECORD
        inputs = [x[i] for i in RECORDED_INPUTS]
        out = []
        for c in range(3):
            # Permute: each slot is one lane's, so the backward scatter needs no conflict handling.
            value = f[c] + dr.gather(mi.Float, segment.probes, base + c, keep, mode=dr.ReduceMode.Permute)
            for j, x_j in enumerate(inputs):
                index = base + 3 + c * len(inputs) + j
                value = dr.fma(dr.gather(mi.Float, segment.probes, index, keep, mode=dr.ReduceMode.Permute), x_j,
                               value)
            out.append(value)
        return out

    def received(self) -> list[tuple]:
        """After the backward pass, before :meth:`stop`: ``(counter, gradient)`` of each trace's
        records that received adjoints (a primal trace receives none), evaluated in one kernel:
        a slot, once taken, cannot be computed again. What :func:`decode_records` reads; inside a
        frozen function, what it returns."""
        pairs = [(s.counter, dr.grad(s.probes)) for s in self._segments]
        pairs = [(counter, grad) for counter, grad in pairs if grad.state != dr.VarState.Literal]
        dr.eval(*[x for pair in pairs for x in pair])
        return pairs


def decode_records(received: list[tuple], capacity: int) -> tuple[np.ndarray, np.ndarray]:
    """The recorded evaluations with a non-zero adjoint (``received``: :meth:`AdjointRecorder.received`):
    network inputs ``(m, 6)`` and output adjoints ``(m, 3)`` (float32, as recorded). Raises
    :class:`RecorderOverflow` where a trace had more evaluations than ``capacity`` (its gradient
    would be incomplete)."""
    inputs, adjoints = [], []
    for counter, grad in received:
        count = int(counter.numpy()[0])
        if count > capacity:
            raise RecorderOverflow(count, capacity)
        if count == 0:
            continue
        values = np.asarray(grad.numpy())[:RECORD * count].reshape(count, RECORD)
        adjoint = values[:, :3]
        kept = np.any(adjoint != 0, axis=1)
        values, adjoint = values[kept], adjoint[kept]
        # x_j from x_j * adjoint_c on the channel of the largest adjoint (float32 products:
        # about 1e-7 relative error).
        channel = np.argmax(np.abs(adjoint), axis=1)
        rows = np.arange(len(values))
        products = values[:, 3:].reshape(-1, 3, len(RECORDED_INPUTS))[rows, channel]
        x = np.zeros((len(values), 6), np.float32)
        x[:, list(RECORDED_INPUTS)] = products / adjoint[rows, channel][:, None]
        inputs.append(x)
        adjoints.append(adjoint)
    if not inputs:
        return np.zeros((0, 6), np.float32), np.zeros((0, 3), np.float32)
    return np.concatenate(inputs), np.concatenate(adjoints)
