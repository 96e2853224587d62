"""A restricted unpickler for model files that should hold nothing but arrays.

Pickle runs code: any global a stream names can be called. :class:`ArrayUnpickler`
overrides ``find_class`` so a stream can only reach

* numpy array, dtype and scalar reconstruction (``numpy.core.multiarray._reconstruct``
  and ``scalar``, also under ``numpy._core``; ``numpy.ndarray``, ``numpy.dtype``;
  ``numpy.core.numeric._frombuffer`` for protocol-5 pickles);
* ``builtins.set``/``frozenset`` (chumpy objects carry an empty set);
* ``_codecs.encode`` restricted to latin-1 text (how Python 3 writes bytes in protocol 2)
  and ``copyreg._reconstructor`` restricted to this module's stand-ins;
* stand-ins defined here for ``chumpy.ch.Ch`` (FLAME 2020 stores some arrays as chumpy
  objects) and ``scipy.sparse`` csc/csr matrices: they only record the pickled state;
  :func:`to_plain` turns them into an ndarray / a scipy sparse matrix built here. No
  chumpy or scipy code from the stream ever runs.

Anything else raises :class:`synth.errors.ModelFormatError` ("refusing to load ...")
before it can be called. Streams are read with ``encoding="latin1"`` so Python 2 pickles
(whose array bytes are ``str``) load too.
"""

from __future__ import annotations

import _compat_pickle
import io
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from synth.errors import ModelFormatError

__all__ = ["ArrayUnpickler", "load_pickle", "load_npy_object", "to_plain", "ChumpyStandIn", "SparseStandIn"]


class _StandIn:
    """Records the pickled state; has no behaviour (not callable, no __reduce__ hooks)."""

    __slots__ = ("state", "args")
    source = "?"

    def __new__(cls, *args, **kwargs):
        obj = object.__new__(cls)
        obj.args = args
        obj.state = None
        return obj

    def __setstate__(self, state):
        self.state = state

    def __repr__(self):
        return f"<{type(self).__name__} of {self.source}>"


class ChumpyStandIn(_StandIn):
    source = "chumpy.ch.Ch"


class SparseStandIn(_StandIn):
    source = "scipy.sparse matrix"
    fmt = ""


class CscStandIn(SparseStandIn):
    fmt = "csc"


class CsrStandIn(SparseStandIn):
    fmt = "csr"


def _safe_reconstructor(cls, base, state):
    """copyreg._reconstructor for stand-ins only (protocol 0/1 object pickles)."""
    if not (isinstance(cls, type) and issubclass(cls, _StandIn)) or base is not object:
        raise ModelFormatError("refusing to load pickle: copyreg._reconstructor on a non-array class", None,
                               "the file must hold only arrays")
    return cls.__new__(cls)


def _safe_codecs_encode(obj, encoding="utf-8", errors="strict"):
    if not isinstance(obj, str) or str(encoding).lower().replace("_", "-") not in ("latin1", "latin-1"):
        raise ModelFormatError("refusing to load pickle: _codecs.encode used for something other than bytes",
                               None, "the file must hold only arrays")
    return obj.encode("latin1")


def _multiarray():
    try:
        from numpy._core import multiarray  # numpy >= 2
    except ImportError:
        from numpy.core import multiarray
    return multiarray


def _numpy_reconstruct(subtype, shape, dtype):
    if subtype is not np.ndarray:
        raise ModelFormatError("refusing to load pickle: array subclass", None, "the file must hold only arrays")
    return _multiarray()._reconstruct(np.ndarray, shape, dtype)


def _numpy_frombuffer(buf, dtype, shape, order):
    return np.frombuffer(buf, dtype=dtype).reshape(shape, order=order).copy()


def _numpy_scalar(dtype, *args):
    return _multiarray().scalar(dtype, *args)


_ALLOWED: dict[tuple[str, str], Any] = {
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
    ("builtins", "object"): object,
    ("copyreg", "_reconstructor"): _safe_reconstructor,
    ("_codecs", "encode"): _safe_codecs_encode,
    ("chumpy.ch", "Ch"): ChumpyStandIn,
    ("chumpy", "Ch"): ChumpyStandIn,
}
for _np in ("numpy.core", "numpy._core"):
    _ALLOWED[(f"{_np}.multiarray", "_reconstruct")] = _numpy_reconstruct
    _ALLOWED[(f"{_np}.multiarray", "scalar")] = _numpy_scalar
    _ALLOWED[(f"{_np}.numeric", "_frombuffer")] = _numpy_frombuffer
for _fmt, _cls in (("csc", CscStandIn), ("csr", CsrStandIn)):
    for _mod in (f"scipy.sparse.{_fmt}", f"scipy.sparse._{_fmt}", "scipy.sparse"):
        _ALLOWED[(_mod, f"{_fmt}_matrix")] = _cls
        _ALLOWED[(_mod, f"{_fmt}_array")] = _cls


class ArrayUnpickler(pickle.Unpickler):
    """``pickle.Unpickler`` that resolves only the globals listed in this module's docstring."""

    def __init__(self, file, where: str = "pickle"):
        super().__init__(file, encoding="latin1", fix_imports=True)
        self.where = where

    def find_class(self, module: str, name: str):
        key = (module, name)
        if key in _compat_pickle.NAME_MAPPING:  # Python 2 names (copy_reg, __builtin__)
            key = _compat_pickle.NAME_MAPPING[key]
        elif module in _compat_pickle.IMPORT_MAPPING:
            key = (_compat_pickle.IMPORT_MAPPING[module], name)
        fn = _ALLOWED.get(key)
        if fn is None:
            raise ModelFormatError(f"refusing to load {self.where}: pickle references {module}.{name}, "
                                   "which is not a plain array", None,
                                   "only numpy arrays (and chumpy/scipy.sparse wrappers of them) are accepted")
        return fn

    def persistent_load(self, pid):
        raise ModelFormatError(f"refusing to load {self.where}: pickle uses persistent ids", None,
                               "only numpy arrays are accepted")


def _loads(data: bytes, where: str) -> Any:
    try:
        return ArrayUnpickler(io.BytesIO(data), where).load()
    except ModelFormatError:
        raise
    except RecursionError:
        raise ModelFormatError(f"cannot read {where}: pickle nests too deeply", None, "check the file") from None
    except Exception as e:  # noqa: BLE001 - any malformed stream is one user error
        raise ModelFormatError(f"cannot read {where}: not a readable pickle ({type(e).__name__}: {e})"[:300], None,
                               "check that the file is the original download") from None


def load_pickle(path: str | Path) -> Any:
    """Load a pickle file through :class:`ArrayUnpickler`."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ModelFormatError(f"cannot read file ({e.strerror or e})", str(path), "check the path") from None
    return _loads(data, str(path))


def load_npy_object(path: str | Path) -> Any:
    """Load an ``.npy`` file; object arrays (e.g. a saved dict) go through the restricted
    unpickler instead of numpy's unrestricted ``allow_pickle``. A 0-d object array is
    returned as its single item."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ModelFormatError(f"cannot read file ({e.strerror or e})", str(path), "check the path") from None
    if not data.startswith(b"\x93NUMPY"):  # a bare pickle saved with an .npy name
        return _loads(data, str(path))
    f = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            shape, fortran, dtype = np.lib.format._read_array_header(f, version)
    except ValueError as e:
        raise ModelFormatError(f"cannot read {path}: bad .npy header ({e})", None, "check the file") from None
    if dtype.hasobject:
        obj = _loads(data[f.tell():], str(path))
        if isinstance(obj, np.ndarray) and obj.shape == () and obj.dtype.hasobject:
            return obj.item()
        return obj
    f.seek(0)
    return np.load(f, allow_pickle=False)


def to_plain(obj: Any, where: str = "pickle") -> Any:
    """Replace stand-ins (recursively in dicts, lists, tuples) by ndarrays / scipy sparse."""
    if isinstance(obj, dict):
        return {k: to_plain(v, where) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(to_plain(v, where) for v in obj)
    if isinstance(obj, ChumpyStandIn):
        st = obj.state
        x = st.get("x") if isinstance(st, dict) else None
        if x is None and obj.args:
            x = obj.args[0]
        x = to_plain(x, where)
        if not isinstance(x, np.ndarray) and np.isscalar(x):
            x = np.asarray(x)
        if not isinstance(x, np.ndarray):
            raise ModelFormatError(f"cannot read {where}: a chumpy object holds no plain array 'x' "
                                   "(derived chumpy expressions are not supported)", None,
                                   "re-save the model with numpy arrays (np.asarray of each entry)")
        return x
    if isinstance(obj, SparseStandIn):
        import scipy.sparse as sp

        st = obj.state if isinstance(obj.state, dict) else {}
        try:
            shape = tuple(int(s) for s in st.get("_shape", st.get("shape")))
            parts = (np.asarray(st["data"]), np.asarray(st["indices"]), np.asarray(st["indptr"]))
            cls = sp.csc_matrix if obj.fmt == "csc" else sp.csr_matrix
            return cls(parts, shape=shape)
        except (KeyError, TypeError, ValueError) as e:
            raise ModelFormatError(f"cannot read {where}: malformed sparse matrix ({e})", None,
                                   "check that the file is the original download") from None
    return obj
