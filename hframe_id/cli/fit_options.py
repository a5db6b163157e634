"""``hframe-id fit``: the parsed command line as ``FitOptions`` (names, pairs, numbers checked)."""

from __future__ import annotations

import argparse

from hframe_id.errors import OptionError
from hframe_id.fitting.options import FitOptions


def _names(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _pairs(items: list[str], what: str) -> dict[str, str]:
    pairs = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name or not value:
            raise OptionError(f"{what} must look like NAME=VALUE, got {item!r}")
        pairs[name.strip()] = value.strip()
    return pairs


def _float(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise OptionError(f"{what}: {text!r} is not a number") from None


def _samples(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise OptionError(f"{what}: {text!r} is not a whole number of samples") from None


def fit_options(args: argparse.Namespace) -> FitOptions:
    """The options of ``hframe-id fit`` from its parsed ``args``; the model's fit defaults are
    not applied yet (an option left unset stays unset). Raises OptionError naming the option
    whose text is malformed."""
    from hframe_id.models.declaration import FIT_DEFAULT_KEYS

    bounds = {}
    for name, text in _pairs(args.bounds, "--bounds").items():
        low, sep, high = text.partition(":")
        if not sep:
            raise OptionError(f"--bounds {name}: expected LOW:HIGH, got {text!r}")
        bounds[name] = (_float(low, f"--bounds {name}"), _float(high, f"--bounds {name}"))
    channel_std = {
        name: _float(value, f"--channel-std {name}")
        for name, value in _pairs(args.channel_std, "--channel-std").items()
    }
    smoothing = None
    if args.smoothing:
        parts = _names(args.smoothing)
        smoothing = tuple(_float(p, "--smoothing") for p in parts)
    extra = {"threads": args.threads} if args.threads is not None else {}
    return FitOptions(
        free=_names(args.free) if args.free is not None else None,
        fix=_names(args.fix),
        bounds=bounds,
        bound_factor=args.bound_factor,
        channel_std=channel_std,
        noise=args.noise,
        solver=args.solver,
        latency_samples={
            name: _samples(value, f"--latency {name}")
            for name, value in _pairs(args.latency, "--latency").items()
        },
        **{
            name: getattr(args, name)
            for name in FIT_DEFAULT_KEYS
            if getattr(args, name) is not None
        },
        smoothing=smoothing,
        smoothing_schedule=tuple(
            _float(p, "--smoothing-schedule") for p in _names(args.smoothing_schedule)
        ),
        first_stage=not args.no_first_stage,
        initial_state=args.initial_state,
        zero_reachable=_names(args.zero_reachable) if args.zero_reachable else (),
        starts=args.starts,
        start_seed=args.start_seed,
        screen_start=not args.start_as_given,
        max_iterations=args.max_iterations,
        step_tol=args.step_tol,
        defect_tol=args.defect_tol,
        identifiability_threshold=args.identifiability_threshold,
        max_misfit=args.max_misfit,
        uncertainty=args.uncertainty,
        consider_method=args.consider_method,
        verbose=0 if args.quiet else 1,
        **extra,
    )
