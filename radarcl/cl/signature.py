"""A kernel's interface, read from its ``.cl`` source: one declaration, checked on every call.

PyOpenCL's reduction and elementwise builders parse C argument declarations
(``pyopencl.tools.parse_c_arg``) so that Python passes named arguments of the right dtype.
radarcl does the same for whole kernel files: ``parse_kernels`` reads every ``__kernel``
signature (comments removed, attributes skipped), and ``KernelFunction`` calls a kernel with
keyword arguments, refusing a missing or unknown name, a host array where a device buffer
belongs, a device array of the wrong shape or dtype where the caller says which it expects, and
a scalar its C type cannot hold. The positional order exists only in the ``.cl`` file.
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError, KernelBuildError, ShapeError

# C scalar types a kernel argument may have, and the numpy dtype each is passed as.
SCALAR_TYPES = {
    "char": np.int8, "uchar": np.uint8, "unsigned char": np.uint8,
    "short": np.int16, "ushort": np.uint16, "unsigned short": np.uint16,
    "int": np.int32, "uint": np.uint32, "unsigned int": np.uint32, "unsigned": np.uint32,
    "long": np.int64, "ulong": np.uint64, "unsigned long": np.uint64,
    "float": np.float32, "double": np.float64,
}
_ADDRESS_SPACES = {"__global": "global", "global": "global", "__local": "local", "local": "local",
                   "__constant": "constant", "constant": "constant", "__private": "private", "private": "private"}
_QUALIFIERS = {"const", "restrict", "__restrict", "volatile", "__read_only", "__write_only", "read_only",
               "write_only"}


@dataclass(frozen=True)
class KernelArg:
    """One parameter of a ``__kernel``: its name, C type (without qualifiers), whether it is a
    pointer, its address space ('global', 'local', 'constant', or 'private' for scalars), and
    whether it is const (an input)."""

    name: str
    ctype: str
    pointer: bool
    space: str
    const: bool

    @property
    def dtype(self):
        """numpy dtype of a scalar argument (None for pointers)."""
        return None if self.pointer else np.dtype(SCALAR_TYPES[self.ctype])


def _strip_comments(source):
    source = re.sub(r"/\*.*?\*/", " ", source, flags=re.S)
    return re.sub(r"//[^\n]*", " ", source)


def _parse_arg(text, kernel, path):
    tokens = re.findall(r"[A-Za-z_]\w*|\*", text)
    if len(tokens) < 2 or not re.fullmatch(r"[A-Za-z_]\w*", tokens[-1]):
        raise KernelBuildError(f"{path}: cannot read argument {text.strip()!r} of kernel {kernel}")
    name, rest = tokens[-1], tokens[:-1]
    pointer = "*" in rest
    space = next((_ADDRESS_SPACES[t] for t in rest if t in _ADDRESS_SPACES), "private")
    const = "const" in rest
    ctype = " ".join(t for t in rest if t != "*" and t not in _ADDRESS_SPACES and t not in _QUALIFIERS)
    if not pointer and ctype not in SCALAR_TYPES:
        raise KernelBuildError(f"{path}: argument {name} of kernel {kernel} has type {ctype!r}; radarcl passes "
                               f"scalars of the types {sorted(SCALAR_TYPES)} only")
    return KernelArg(name, ctype, pointer, space, const)


# What follows the word __kernel: attributes, then "void name(".
_HEAD = re.compile(r"\s*(?:__attribute__\s*\(\((?:[^()]|\([^()]*\))*\)\)\s*)*void\s+([A-Za-z_]\w*)\s*\(")


def parse_kernels(source, path="<source>"):
    """{kernel name: (KernelArg, ...)} for every ``__kernel`` in an OpenCL C source."""
    text = _strip_comments(source)
    out = {}
    for match in re.finditer(r"\b(?:__kernel|kernel)\b", text):
        m = _HEAD.match(text, match.end())
        if not m:
            continue                            # e.g. the word in a string or a macro
        name, start, depth = m.group(1), m.end(), 1
        i = start
        while depth and i < len(text):
            depth += {"(": 1, ")": -1}.get(text[i], 0)
            i += 1
        if depth:
            raise KernelBuildError(f"{path}: unbalanced parentheses in the signature of kernel {name}")
        params = text[start:i - 1].strip()
        args = () if params in ("", "void") else tuple(_parse_arg(p, name, path) for p in params.split(","))
        names = [a.name for a in args]
        if len(set(names)) != len(names):
            raise KernelBuildError(f"{path}: kernel {name} repeats an argument name: {names}")
        out[name] = args
    return out


def device_array(value, what):
    """The buffer of a device argument: a ``pyopencl.array.Array`` or a ``pyopencl.Buffer``;
    anything else (a numpy array, None) is refused with the argument's name."""
    import pyopencl as cl
    import pyopencl.array as cla

    if isinstance(value, cla.Array):
        return value.base_data if value.offset == 0 else value.data
    if isinstance(value, cl.MemoryObject):
        return value
    raise ShapeError(f"{what} must be a device array (pyopencl.array.Array) or buffer, got {type(value).__name__}")


def scalar_value(arg, value, kernel):
    """A scalar argument converted to its C type, or ConfigError when it cannot hold it."""
    return _converter(arg, kernel)(value)


def _converter(arg, kernel):
    """``scalar_value`` for one argument, its dtype and limits looked up once (np.dtype,
    np.iinfo and np.finfo cost microseconds a call, and a moving radar's frame makes three
    launches of about 20 scalars)."""
    dtype = arg.dtype
    to_c = dtype.type
    integer = dtype.kind in "iu"
    info = np.iinfo(dtype) if integer else np.finfo(dtype)
    lo, hi = info.min, info.max

    def convert(value):
        if isinstance(value, (bool, np.bool_)):
            raise ConfigError(f"{kernel}: {arg.name} must be a number, got {value!r}")
        if integer:
            if not float(value).is_integer():
                raise ConfigError(f"{kernel}: {arg.name} must be an integer, got {value!r}")
            if not lo <= int(value) <= hi:
                raise ConfigError(f"{kernel}: {arg.name} = {value} does not fit {arg.ctype} [{lo}, {hi}]")
            return to_c(int(value))
        v = float(value)
        if math.isnan(v) or (math.isfinite(v) and abs(v) > hi):
            raise ConfigError(f"{kernel}: {arg.name} = {value!r} is not a {arg.ctype} value")
        return to_c(v)

    return convert


class KernelFunction:
    """One kernel called by argument name (see the module docstring).

    ``function(queue, global_size, local_size, wait_for=None, **arguments)`` returns the event.
    """

    def __init__(self, kernel, args, path):
        self.kernel, self.args, self.path = kernel, tuple(args), path
        self.name = kernel.function_name
        self.names = tuple(a.name for a in self.args)
        self._name_set = frozenset(self.names)
        self._convert = tuple(None if a.pointer else _converter(a, self.name) for a in self.args)
        kernel.set_scalar_arg_dtypes([None if a.pointer else a.dtype for a in self.args])

    def __call__(self, queue, global_size, local_size, *, wait_for=None, global_offset=None, **arguments):
        given = arguments.keys()
        if given != self._name_set:
            missing = [n for n in self.names if n not in given]
            unknown = sorted(given - self._name_set)
            raise ConfigError(f"kernel {self.name} ({self.path.name}) takes {', '.join(self.names)}; "
                              + (f"missing {missing}" if missing else "")
                              + ("; " if missing and unknown else "")
                              + (f"unknown {unknown}" if unknown else ""))
        values = [device_array(arguments[name], f"{self.name}: {name}") if convert is None else convert(arguments[name])
                  for name, convert in zip(self.names, self._convert)]
        return self.kernel(queue, global_size, local_size, *values, global_offset=global_offset, wait_for=wait_for)
