"""seqloc: sequence localization against OpenStreetMap, for Python tools (docs/python.md).

Region caches (map crops, road distance, road prior), route folders and the output folders of
``seqloc localize``, the SeqLoc filter over a window of cells, and localize's localizer one
frame at a time, for a loop that brings its own volumes (a PyTorch backbone's, say). Results are
typed objects; headings named ``heading_deg`` are compass headings (clockwise from true north),
grid values are named as such (``grid_heading_deg``, window cells ``u``, ``v``, region metres
``x_m``, ``y_m``).
"""

from ._seqloc import (
    Cache as Cache,
    CacheError as CacheError,
    CacheInfo as CacheInfo,
    Crop as Crop,
    DataError as DataError,
    Error as Error,
    Filter as Filter,
    FilterError as FilterError,
    FilterResult as FilterResult,
    InternalError as InternalError,
    IOError as IOError,
    Localizer as Localizer,
    Metrics as Metrics,
    NotFoundError as NotFoundError,
    Pose as Pose,
    RequestError as RequestError,
    Route as Route,
    RouteFrame as RouteFrame,
    RunFolder as RunFolder,
    UsageError as UsageError,
    UsageIndexError as UsageIndexError,
    UsageKeyError as UsageKeyError,
    UsageTypeError as UsageTypeError,
    WindowPose as WindowPose,
    __version__ as __version__,
    cuda_status as cuda_status,
)

__all__ = [
    "Cache",
    "CacheError",
    "CacheInfo",
    "Crop",
    "DataError",
    "Error",
    "Filter",
    "FilterError",
    "FilterResult",
    "InternalError",
    "IOError",
    "Localizer",
    "Metrics",
    "NotFoundError",
    "Pose",
    "RequestError",
    "Route",
    "RouteFrame",
    "RunFolder",
    "UsageError",
    "UsageIndexError",
    "UsageKeyError",
    "UsageTypeError",
    "WindowPose",
    "cuda_status",
]
