"""Type stubs of epfilt's Python API (see the module's docstrings)."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt
from typing_extensions import TypedDict, Unpack

__version__: str

_Path = Union[str, "PathLike[str]"]
_Samples = Union[npt.NDArray[np.float32], npt.NDArray[np.float16], npt.NDArray[np.float64]]

# The settings `filter_file` and `filter` take by keyword: the command line's
# options with underscores (`epfilt filter --help`), checked against the library's
# tables by a test (`epfilt._epfilt.settings()`).
_Value = Union[str, int, float]

class ArraySettings(TypedDict, total=False):
    nonfinite: _Value
    variance_kind: _Value
    guides: _Value
    guide: Sequence[str]
    guide_normal: _Value
    guide_albedo: _Value
    guide_depth: _Value
    pixel_type: _Value
    threads: _Value
    oversubscribe: bool
    tile: _Value
    strip_rows: _Value
    window_blocks: _Value
    geometry_threads: _Value
    strips_in_flight: _Value
    d: _Value
    nmid: _Value
    ltvis: _Value
    confidence: _Value
    passes: _Value
    quality: _Value
    clamp: _Value
    tolerance: _Value
    radius: _Value
    max_radius: _Value
    cutoff: _Value
    width_step: _Value
    support: _Value
    support_ratio: _Value
    support_group: _Value
    support_compact: _Value
    support_over: _Value
    support_region: _Value
    support_level: _Value
    coarse_from: _Value
    bound_from: _Value
    guard: _Value
    guard_confidence: _Value
    carriers: _Value
    carriers_fraction: _Value
    carriers_rse: _Value
    alpha: _Value

# `filter_file` takes every setting `filter` does, and those naming files,
# their layout, and what `filter` takes as its own parameters.
class FilterSettings(ArraySettings, total=False):
    supersample: _Value
    part: _Value
    edge: _Value
    method: _Value
    variance_channel: _Value
    spp: _Value
    spp_channel: _Value
    layer: _Value
    view: _Value
    channel_rule: Sequence[str]
    format: _Value
    compression: _Value
    allow_lossy: bool
    frames: _Value
    task_index: _Value
    task_count: _Value
    skip_existing: bool
    fail_fast: bool
    keep_going: bool
    band: _Value
    band_index: _Value
    band_count: _Value
    max_memory: _Value

# The settings `restore_file` takes by keyword (`epfilt restore --help`), and
# those of them `restore` takes (not naming files; `scale` is its own parameter).
class RestoreArraySettings(TypedDict, total=False):
    nonfinite: _Value
    guides: _Value
    guide: Sequence[str]
    threads: _Value
    keep_gain: _Value

class RestoreSettings(RestoreArraySettings, total=False):
    part: _Value
    layer: _Value
    channel_rule: Sequence[str]
    compression: _Value
    max_memory: _Value
    scale: _Value

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
    **settings: Unpack[ArraySettings],
) -> Tuple[_Samples, Dict[str, Any]]: ...
def filter_file(
    input: _Path,
    output: _Path,
    *,
    progress: Optional[Callable[[int, int], Any]] = None,
    **settings: Unpack[FilterSettings],
) -> Dict[str, Any]: ...
def restore(
    denoised: _Samples,
    energy: _Samples,
    scale: Optional[int] = None,
    *,
    emission: Optional[_Samples] = None,
    variance: Optional[npt.NDArray[Any]] = None,
    spp: Union[int, float, npt.NDArray[Any], None] = None,
    channels: Optional[Sequence[str]] = None,
    **settings: Unpack[RestoreArraySettings],
) -> Tuple[npt.NDArray[np.float32], Dict[str, Any]]: ...
def restore_file(
    denoised: _Path,
    energy: _Path,
    output: _Path,
    *,
    progress: Optional[Callable[[int, int], Any]] = None,
    **settings: Unpack[RestoreSettings],
) -> Dict[str, Any]: ...
def denoise_file(
    render: _Path,
    output: _Path,
    *,
    denoised: Optional[_Path] = None,
    quality: str = "high",
    progress: Optional[Callable[[int, int], Any]] = None,
    **restore_settings: Unpack[RestoreSettings],
) -> Dict[str, Any]: ...
def info(path: _Path) -> Dict[str, Any]: ...
def compare(a: _Path, b: _Path) -> Dict[str, Any]: ...
def read(path: _Path, extra: Optional[Sequence[str]] = None) -> Tuple[npt.NDArray[np.float32], List[str]]: ...
