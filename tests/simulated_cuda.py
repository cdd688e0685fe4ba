"""A CUDA device simulated on the CPU, for the device bugs that a CPU-only run cannot show.

CI has no GPU, and code that runs on the CPU can still mix devices: a tensor built on the CPU
meets one on the GPU, or a GPU tensor goes to NumPy without ``.cpu()``. Inside
:func:`simulated_cuda`, ``torch.cuda.is_available()`` is true, and every tensor placed on
"cuda" (by a ``device=`` argument, ``.to``, ``.cuda()``, or as the result of an operation on
such tensors) is a CPU tensor of the class :class:`SimulatedCuda` whose ``device`` reads
``cuda:0``. Every torch operation is checked as CUDA checks it:

- tensors of both devices in one operation raise, except CPU scalars (0-dim), copies
  (``copy_``, ``to``) and indexing a CUDA tensor with CPU indices;
- a CUDA tensor handed to NumPy (``.numpy()``, ``np.asarray``) raises;
- a random draw on "cuda" with a CPU generator raises.

The arithmetic is the CPU's, so results equal a CPU run's; only the bookkeeping is extra (a
few times slower). Parameters made from such tensors are :class:`SimulatedCudaParameter`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from unittest import mock

import torch
import torch.utils._pytree as pytree
from torch.autograd.function import BackwardCFunction
from torch.overrides import TorchFunctionMode

CUDA = torch.device("cuda", 0)


class _OnCuda:
    """What makes a CPU tensor read as one on the GPU."""

    _simulated_cuda = True

    @property
    def device(self) -> torch.device:
        return CUDA

    @property
    def is_cuda(self) -> bool:
        return True


class SimulatedCuda(_OnCuda, torch.Tensor):
    """A CPU tensor that stands for one on the GPU (see the module's docstring)."""

    __torch_function__ = torch._C._disabled_torch_function_impl


class SimulatedCudaParameter(_OnCuda, torch.nn.Parameter):
    """A parameter on the simulated GPU."""


def on_cuda(t) -> bool:
    """Whether a tensor stands on the simulated GPU."""
    return isinstance(t, torch.Tensor) and getattr(type(t), "_simulated_cuda", False)


def _wants(device) -> bool | None:
    """True for a CUDA device, False for the CPU, None when no device is named."""
    if device is None:
        return None
    if isinstance(device, torch.Tensor):
        return on_cuda(device)
    if isinstance(device, int):
        return True  # a bare index names a CUDA device
    kind = torch.device(device).type
    if kind not in ("cpu", "cuda"):
        return None
    return kind == "cuda"


def _to_target(args, kwargs) -> bool | None:
    """The device that ``Tensor.to(*args, **kwargs)`` asks for (see _wants)."""
    if "device" in kwargs:
        return _wants(kwargs["device"])
    if "other" in kwargs:
        return _wants(kwargs["other"])
    for a in args[1:]:
        if isinstance(a, (str, torch.device, torch.Tensor, int)) and not isinstance(a, bool):
            return _wants(a)
    return None


def _device_free(kwargs: dict) -> dict:
    """kwargs with a CUDA ``device`` named as the CPU."""
    if _wants(kwargs.get("device")):
        return {**kwargs, "device": "cpu"}
    return kwargs


def _place(x, cuda: bool, inputs: set[int]):
    """A result marked as on the simulated GPU (cuda) or the CPU. The class of the very tensor
    changes, so its autograd history and in-place updates stay as they are; an input that comes
    back on the other device is copied first, as a real move copies."""
    if not isinstance(x, torch.Tensor) or on_cuda(x) == cuda:
        return x
    if id(x) in inputs:
        x = x.clone()
    if isinstance(x, torch.nn.Parameter):
        x.__class__ = SimulatedCudaParameter if cuda else torch.nn.Parameter
    else:
        x.__class__ = SimulatedCuda if cuda else torch.Tensor
    return x


_MOVES = {torch.Tensor.to, torch.Tensor.cuda, torch.Tensor.cpu}
_INDEXING = {torch.Tensor.__getitem__, torch.Tensor.__setitem__}
_TO_NUMPY = {torch.Tensor.numpy, torch.Tensor.__array__}


def _check(func, args, tensors: list[torch.Tensor]) -> None:
    """Raise where CUDA would: both devices in one operation (see the module's docstring)."""
    if func in _MOVES or func is torch.Tensor.copy_:
        return
    if func in _INDEXING:
        index = [t for t in pytree.tree_leaves(args[1]) if isinstance(t, torch.Tensor)]
        if not on_cuda(args[0]) and any(on_cuda(t) for t in index):
            raise RuntimeError(
                "indices should be either on cpu or on the same device as the indexed tensor (cpu) (simulated CUDA)"
            )
        return
    cuda = [t for t in tensors if on_cuda(t)]
    cpu = [t for t in tensors if not on_cuda(t) and t.dim() > 0]
    if cuda and cpu:
        raise RuntimeError(
            "Expected all tensors to be on the same device, but found at least two devices, cuda:0 and cpu! "
            f"(simulated CUDA, in {getattr(func, '__name__', func)})"
        )


class _Mode(TorchFunctionMode):
    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        tensors = [x for x in pytree.tree_leaves((args, kwargs)) if isinstance(x, torch.Tensor)]
        inputs = {id(t) for t in tensors}
        if func in _TO_NUMPY and any(on_cuda(t) for t in tensors):
            raise TypeError("can't convert cuda:0 device type tensor to numpy. Use Tensor.cpu() first (simulated CUDA)")
        if func in _MOVES:
            if func is torch.Tensor.to:
                cuda = _to_target(args, kwargs)
                rest = tuple("cpu" if isinstance(a, (str, torch.device)) and _wants(a) else a for a in args[1:])
                rest = tuple(a for a in rest if not (isinstance(a, int) and not isinstance(a, bool)))
                out = func(args[0], *rest, **_device_free(kwargs))
            else:
                cuda, out = func is torch.Tensor.cuda, args[0]
            return _place(out, on_cuda(args[0]) if cuda is None else cuda, inputs)
        named = _wants(kwargs.get("device"))
        generator = kwargs.get("generator")
        if named and isinstance(generator, torch.Generator) and generator.device.type == "cpu":
            raise RuntimeError("Expected a 'cuda' device type for generator but found 'cpu' (simulated CUDA)")
        _check(func, args, tensors)
        out = func(*args, **_device_free(kwargs))
        if func is torch.Tensor.__setitem__:
            return out
        if func is torch.Tensor.__getitem__:
            cuda = on_cuda(args[0])
        else:
            cuda = named if named is not None else any(on_cuda(t) for t in tensors)
        return pytree.tree_map(lambda x: _place(x, cuda, inputs), out)


def _parameter_new(original):
    def new(cls, data=None, requires_grad=True):
        p = original(cls, data, requires_grad)
        if data is not None and on_cuda(data):
            p.__class__ = SimulatedCudaParameter
        return p

    return new


_BASE_SAVED = torch._C._FunctionBase.saved_tensors


def _node_on_cuda(ctx) -> bool:
    """Whether a custom autograd Function's node ran on the simulated GPU."""
    tensors = [*_BASE_SAVED.__get__(ctx), *(v for v in vars(ctx).values() if isinstance(v, torch.Tensor))]
    return any(on_cuda(t) for t in tensors)


def _saved_tensors(ctx):
    """ctx.saved_tensors, placed on the simulated GPU with their node."""
    saved = _BASE_SAVED.__get__(ctx)
    if _node_on_cuda(ctx):
        return tuple(_place(t, True, set()) for t in saved)
    return saved


def _user_fn(original):
    """A custom Function's backward, run as CUDA would run it: the autograd engine runs it
    outside the torch-function mode, so the mode is entered again, and the incoming gradients
    are on the node's device."""

    def get(ctx):
        fn = original(ctx)

        def backward(ctx, *grads):
            if _node_on_cuda(ctx):
                grads = tuple(_place(g, True, set()) for g in grads)
            with _Mode():
                return fn(ctx, *grads)

        return backward

    return get


@contextlib.contextmanager
def simulated_cuda() -> Iterator[None]:
    """Run the block as if a CUDA device were present (see the module's docstring)."""
    patches = [
        mock.patch("torch.cuda.is_available", lambda: True),
        mock.patch("torch.cuda.synchronize", lambda *a, **k: None),
        mock.patch("torch.cuda.device_count", lambda: 1),
        mock.patch("torch.cuda.get_device_name", lambda *a, **k: "simulated CUDA"),
        mock.patch.object(torch.nn.Parameter, "__new__", _parameter_new(torch.nn.Parameter.__new__)),
        mock.patch.object(BackwardCFunction, "_get_user_fn", _user_fn(BackwardCFunction._get_user_fn)),
        mock.patch.object(BackwardCFunction, "saved_tensors", property(_saved_tensors), create=True),
    ]
    with contextlib.ExitStack() as stack:
        for p in patches:
            stack.enter_context(p)
        stack.enter_context(_Mode())
        yield
