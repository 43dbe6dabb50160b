"""A pretend CUDA device on the CPU, to catch device mix-ups without a GPU.

:class:`FakeCuda` is a ``TorchFunctionMode``.  A tensor "on" the fake device is
an ordinary CPU tensor that carries a tag; inside the mode

* factory calls with ``device="cuda"`` (``torch.zeros(..., device=...)``,
  ``torch.tensor(..., device=...)``, ``x.new_zeros(...)``) give tagged tensors,
  and ``.to("cuda")`` / ``.cuda()`` give tagged *copies*, as a real transfer does;
* ``.cpu()`` / ``.to("cpu")`` of a tagged tensor give an untagged copy;
* a tagged tensor reports ``device == cuda:0`` and ``is_cuda``;
* every other op refuses, like CUDA does, to mix tagged tensors with untagged
  ones of one or more dimensions (untagged 0-d tensors pass, as CPU scalars do
  on CUDA), except the cross-device copies ``copy_`` and basic-index
  ``__setitem__``, and indexing a tagged tensor with untagged indices;
* ``.numpy()`` of a tagged tensor fails as it does for a CUDA tensor;
* whatever an op returns is tagged when one of its inputs was.

So a pipeline that works inside the mode keeps its tensors on ``backend.device``
the way a CUDA run needs; one that creates a host tensor and mixes it with
backend tensors fails here with the error a GPU run would give.
``with mode.suspended():`` runs code (a wrapped CPU backend) untouched.
"""

from __future__ import annotations

from contextlib import contextmanager

import torch
from torch.overrides import TorchFunctionMode

FAKE = torch.device("cuda", 0)
_TAG = "_droidw_fake_cuda"

_PROPERTY_DEVICE = torch.Tensor.device.__get__
_PROPERTY_IS_CUDA = torch.Tensor.is_cuda.__get__
_TO_HOST_ARRAY = (torch.Tensor.numpy, torch.Tensor.__array__)


def _one_of(func, *candidates) -> bool:
    """``func`` is one of these (by ==: property getters are new method-wrappers at every access)."""
    return any(func == c for c in candidates)


def is_fake(t) -> bool:
    return isinstance(t, torch.Tensor) and getattr(t, _TAG, False)


def _tag(t: torch.Tensor, on: bool) -> None:
    setattr(t, _TAG, on)


def _tensors(obj, out: list) -> list:
    """Every tensor inside nested lists, tuples and dicts."""
    if isinstance(obj, torch.Tensor):
        out.append(obj)
    elif isinstance(obj, (list, tuple)):
        for x in obj:
            _tensors(x, out)
    elif isinstance(obj, dict):
        for x in obj.values():
            _tensors(x, out)
    return out


def _is_fake_device(d) -> bool:
    if isinstance(d, str):
        d = torch.device(d)
    return isinstance(d, torch.device) and d.type == "cuda"


def _host_device(d):
    """The device argument with the fake device replaced by the CPU."""
    return torch.device("cpu") if _is_fake_device(d) else d


def _mix_error(func) -> RuntimeError:
    name = getattr(func, "__name__", str(func))
    return RuntimeError(f"Expected all tensors to be on the same device, but found at least two devices, "
                        f"cuda:0 and cpu! (fake device, in {name})")


class FakeCuda(TorchFunctionMode):
    """The mode (module docstring).  ``device`` is what a spy backend reports."""

    device = torch.device("cuda")

    def __init__(self) -> None:
        super().__init__()
        self._suspended = 0
        self._as_subclass = None

    def __enter__(self):
        # Tensor.as_subclass (pypose's LieTensor ↔ Tensor) makes a new Python object that no
        # mode sees: pass the tag on to it.
        self._as_subclass = torch.Tensor.__dict__.get("as_subclass")
        original = torch.Tensor.as_subclass

        def as_subclass(t, cls):
            out = original(t, cls)
            if is_fake(t):
                _tag(out, True)
            return out

        torch.Tensor.as_subclass = as_subclass
        return super().__enter__()

    def __exit__(self, *exc):
        if self._as_subclass is None:
            del torch.Tensor.as_subclass  # inherited from torch._C.TensorBase again
        else:
            torch.Tensor.as_subclass = self._as_subclass
        return super().__exit__(*exc)

    @contextmanager
    def suspended(self):
        """Run the body with no tagging or checks (a wrapped CPU backend)."""
        self._suspended += 1
        try:
            yield
        finally:
            self._suspended -= 1

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = dict(kwargs or {})
        if self._suspended:
            return func(*args, **kwargs)
        if func == _PROPERTY_DEVICE:
            return FAKE if is_fake(args[0]) else func(*args, **kwargs)
        if func == _PROPERTY_IS_CUDA:
            return True if is_fake(args[0]) else func(*args, **kwargs)
        if _one_of(func, *_TO_HOST_ARRAY) and is_fake(args[0]):
            raise TypeError("can't convert cuda:0 device type tensor to numpy. Use Tensor.cpu() to copy the "
                            "tensor to host memory first. (fake device)")
        if func == torch.Tensor.cpu:
            return self._moved(func(*args, **kwargs), args[0], False)
        if func == torch.Tensor.cuda:
            return self._moved(func(args[0]), args[0], True)
        if func == torch.Tensor.to:
            return self._to(func, args, kwargs)
        target = None
        if "device" in kwargs:
            target = _is_fake_device(kwargs["device"])
            kwargs["device"] = _host_device(kwargs["device"])
        inputs = _tensors(args, []) + _tensors(kwargs, [])
        fake = any(is_fake(t) for t in inputs)
        self._check(func, args, inputs, fake)
        out = func(*args, **kwargs)
        if _one_of(func, torch.Tensor.copy_, torch.Tensor.__setitem__):
            return out  # in place: the destination keeps its device
        on = fake if target is None else target
        for t in _tensors(out, []):
            _tag(t, on)
        return out

    def _check(self, func, args, inputs, fake: bool) -> None:
        if not fake or func == torch.Tensor.copy_:  # copy_ may read another device
            return
        if func == torch.Tensor.__getitem__:
            if not is_fake(args[0]):
                raise RuntimeError("indices should be either on cpu or on the same device as the indexed "
                                   "tensor (cpu) (fake device)")
            return  # a device tensor indexed by host indices is fine
        if func == torch.Tensor.__setitem__:
            dest, index, value = args[0], args[1], args[2]
            index_tensors = _tensors(index, [])
            if not is_fake(dest) and any(is_fake(t) for t in index_tensors):
                raise _mix_error(func)
            if index_tensors and isinstance(value, torch.Tensor) and value.dim() > 0 \
                    and is_fake(value) != is_fake(dest):
                raise _mix_error(func)  # advanced indexing puts values of the destination's device only
            return
        if any(not is_fake(t) and t.dim() > 0 for t in inputs):
            raise _mix_error(func)

    @staticmethod
    def _moved(out: torch.Tensor, src: torch.Tensor, on: bool) -> torch.Tensor:
        """A transfer: a copy when the tag changes (on the CPU ``.to`` may return ``src`` itself)."""
        if is_fake(src) != on and out is src:
            out = out.clone()
        _tag(out, on)
        return out

    def _to(self, func, args, kwargs):
        src = args[0]
        rest = list(args[1:])
        target = None  # None: the device does not change
        if "device" in kwargs:
            target = _is_fake_device(kwargs["device"])
            kwargs["device"] = _host_device(kwargs["device"])
        for n, a in enumerate(rest):
            if isinstance(a, (str, torch.device)):
                target = _is_fake_device(a)
                rest[n] = _host_device(a)
            elif isinstance(a, torch.Tensor):
                target = is_fake(a)
        out = func(src, *rest, **kwargs)
        return self._moved(out, src, is_fake(src) if target is None else target)
