"""``hframe-id cache info|clear``: where compiled native code is kept, how much, and emptying it.

The cache (``hframe_id.native``) only saves compiler runs: clearing it is always safe, the
next simulation or fit rebuilds what it needs (1-2 s per library). A damaged library heals
itself (it is rebuilt when it does not load), and a cache folder that cannot be used costs
fits and simulations one warning (they keep their libraries for the run only), while
``cache info`` and ``cache clear`` refuse it in one line.
"""

from __future__ import annotations

import argparse

from hframe_id.cli.outputs import check_dir


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``cache`` subcommand (``info``, ``clear``)."""
    parser = subparsers.add_parser(
        "cache",
        help="show or clear the cache of compiled native code",
        description="Show the folder and size of the native-code cache (simulators, closed "
        "loop, fitter kernels compiled from CasADi), or delete its contents. The folder is "
        "$HFRAME_ID_CACHE/native, else ~/.cache/hframe-id/native.",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions.add_parser("info", help="print the cache folder, its libraries and size")
    actions.add_parser("clear", help="delete every cached library")
    parser.set_defaults(handler=run)


def _size(size: int) -> str:
    """``size`` [bytes] in MiB, one decimal."""
    return f"{size / 2**20:.1f} MiB"


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id cache info|clear``; a cache folder that cannot be used (it, or a folder
    above it, is a file; it cannot be written) is one error line."""
    from hframe_id import native

    check_dir(native.cache_directory(), "cache folder ($HFRAME_ID_CACHE/native)")
    if args.action == "clear":
        freed = native.clear_cache()
        print(f"cleared {native.cache_directory()} ({_size(freed)} freed)")
        return 0
    info = native.cache_info()
    print(f"folder: {info.folder}")
    print(
        f"libraries: {info.libraries}, {_size(info.size)} (limit {_size(native.MAX_CACHE_BYTES)})"
    )
    return 0
