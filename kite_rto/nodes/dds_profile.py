"""The DDS settings shipped with the package: a Fast DDS XML profile, put in force before ``rclpy.init``.

``config/fastdds_profile.xml`` (installed as ``share/kite_rto/config/fastdds_profile.xml``) gives every reliable
writer a 50 ms heartbeat period (Fast DDS's default: 3 s), so that a reader that was frozen catches up within
about 0.05-0.1 s instead of about 1 s. :func:`use_shipped_profile` points Fast DDS at it through the environment of the
node's own process (Fast DDS reads the variable when rclpy creates the first participant), unless the user chose
otherwise: ``FASTRTPS_DEFAULT_PROFILES_FILE`` or ``FASTDDS_DEFAULT_PROFILES_FILE`` already set (the user's own
profile wins), a ``DEFAULT_FASTRTPS_PROFILES.xml`` in the working directory (Fast DDS loads that one by itself), or
``KITE_RTO_DDS_PROFILE=none`` (Fast DDS's defaults).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

try:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
except ImportError:          # a pip install without ament_index_python: the other places are searched
    get_package_share_directory = None

__all__ = ["PROFILE_FILE", "PROFILE_ENV", "OPT_OUT_ENV", "shipped_profile", "use_shipped_profile"]

PROFILE_FILE = "fastdds_profile.xml"
PROFILE_ENV = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
"""Fast DDS 2 (ROS 2 Jazzy) reads the first, Fast DDS 3 the second."""
OPT_OUT_ENV = "KITE_RTO_DDS_PROFILE"
"""``none`` (or ``off``, ``0``): do not set a profile; Fast DDS runs with its defaults."""
_CWD_DEFAULT = "DEFAULT_FASTRTPS_PROFILES.xml"


def _share_dir() -> Path | None:
    """``share/kite_rto`` of a colcon install (ament index), or None when kite_rto is not in the index."""
    if get_package_share_directory is None:
        return None
    try:
        return Path(get_package_share_directory("kite_rto"))
    except (PackageNotFoundError, LookupError, OSError, ValueError):     # not in the index, or no index at all
        return None


def shipped_profile() -> Path | None:
    """Where the shipped profile is: the source checkout's ``config/`` next to the package (a clone, the
    virtual environment's editable install), else the ament index's ``share/kite_rto/config/`` (colcon install),
    else ``<sys.prefix>/share/kite_rto/config/`` (a pip install's data files); None if in none of them."""
    for where in (lambda: Path(__file__).resolve().parents[2], _share_dir,
                  lambda: Path(sys.prefix) / "share" / "kite_rto"):
        folder = where()
        if folder is not None and (folder / "config" / PROFILE_FILE).is_file():
            return folder / "config" / PROFILE_FILE
    return None


def use_shipped_profile(environ=None) -> tuple[str | None, str]:
    """Set ``FASTRTPS_DEFAULT_PROFILES_FILE`` and ``FASTDDS_DEFAULT_PROFILES_FILE`` in ``environ`` (default
    ``os.environ``) to the shipped profile unless the user chose otherwise (module docstring).

    Returns ``(profile in force or None, why)``, ``why`` a short phrase for the node's start-up log.
    """
    env = os.environ if environ is None else environ
    if env.get(OPT_OUT_ENV, "").strip().lower() in ("none", "off", "0", "false"):
        return None, f"{OPT_OUT_ENV}={env[OPT_OUT_ENV]}: Fast DDS defaults"
    for name in PROFILE_ENV:
        if name in env:
            return (env[name] or None), f"the user's {name}"
    if Path(_CWD_DEFAULT).is_file():
        return str(Path(_CWD_DEFAULT).resolve()), f"the user's {_CWD_DEFAULT} in the working directory"
    path = shipped_profile()
    if path is None:
        return None, f"{PROFILE_FILE} not found (not installed?): Fast DDS defaults"
    for name in PROFILE_ENV:
        env[name] = str(path)
    return str(path), "shipped with kite_rto"
