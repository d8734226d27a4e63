"""Type stubs of epfilt's Python API (see the module's docstrings)."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "PathLike[str]"]
_Samples = Union[npt.NDArray[np.float32], npt.NDArray[np.float16], npt.NDArray[np.float64]]
_Setting = Union[str, int, float, bool, Sequence[str], None]

class Error(Exception): ...
class InputError(Error): ...
class ConfigError(Error, ValueError): ...
class IoError(Error, OSError): ...

def filter(
    samples: _Samples,
    supersample: Optional[int] = None,
    method: Optional[str] = None,
    *,
    channels: Optional[Sequence[str]] = None,
    variance: Optional[npt.NDArray[Any]] = None,
    spp: Union[int, float, npt.NDArray[Any], None] = None,
    **settings: _Setting,
) -> Tuple[_Samples, Dict[str, Any]]: ...
def filter_file(
    input: _Path,
    output: _Path,
    *,
    progress: Optional[Callable[[int, int], Any]] = None,
    **settings: _Setting,
) -> Dict[str, Any]: ...
def restore(
    denoised: _Samples,
    energy: _Samples,
    scale: Optional[int] = None,
    *,
    keep_gain: Optional[float] = None,
    emission: Optional[_Samples] = None,
    variance: Optional[npt.NDArray[Any]] = None,
    spp: Union[int, float, npt.NDArray[Any], None] = None,
    channels: Optional[Sequence[str]] = None,
    threads: int = 0,
    nonfinite: str = "error",
) -> Tuple[npt.NDArray[np.float32], Dict[str, Any]]: ...
def restore_file(
    denoised: _Path,
    energy: _Path,
    output: _Path,
    *,
    scale: Optional[int] = None,
    keep_gain: Optional[float] = None,
    guides: str = "auto",
    guide: Optional[Sequence[str]] = None,
    part: Optional[str] = None,
    layer: Optional[str] = None,
    channel_rule: Optional[Sequence[str]] = None,
    compression: Optional[str] = None,
    threads: int = 0,
    max_memory: Optional[int] = None,
    nonfinite: str = "error",
    progress: Optional[Callable[[int, int], Any]] = None,
) -> Dict[str, Any]: ...
def denoise_file(
    render: _Path,
    output: _Path,
    *,
    denoised: Optional[_Path] = None,
    quality: str = "high",
    scale: Optional[int] = None,
    keep_gain: Optional[float] = None,
    guides: str = "auto",
    guide: Optional[Sequence[str]] = None,
    part: Optional[str] = None,
    layer: Optional[str] = None,
    channel_rule: Optional[Sequence[str]] = None,
    compression: Optional[str] = None,
    threads: int = 0,
    max_memory: Optional[int] = None,
    nonfinite: str = "error",
    progress: Optional[Callable[[int, int], Any]] = None,
) -> Dict[str, Any]: ...
def info(path: _Path) -> Dict[str, Any]: ...
def compare(a: _Path, b: _Path) -> Dict[str, Any]: ...
def read(path: _Path, extra: Optional[Sequence[str]] = None) -> Tuple[npt.NDArray[np.float32], List[str]]: ...
