"""``hframe-id fit``: the parsed command line as ``FitOptions`` (names, pairs, numbers checked)."""

from __future__ import annotations

import argparse
from dataclasses import fields

from hframe_id.errors import OptionError
from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.strategy_settings import StrategySettings


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


def _whole(text: str, what: str, of: str = "") -> int:
    try:
        return int(text)
    except ValueError:
        raise OptionError(f"{what}: {text!r} is not a whole number{of}") from None


def _settings(kind: type, items: list[str], flag: str):
    """``kind`` (``GaussNewtonSettings`` or ``StrategySettings``) with the SETTING=VALUE
    ``items`` given to ``flag`` in place of its defaults, each value read as its default
    is (a whole number, a number, or comma-separated numbers for a tuple)."""
    defaults = kind()
    known = [f.name for f in fields(kind)]
    changes = {}
    for name, text in _pairs(items, flag).items():
        if name not in known:
            raise OptionError(f"{flag}: no setting {name!r} (settings: {', '.join(known)})")
        default, what = getattr(defaults, name), f"{flag} {name}"
        if isinstance(default, tuple):
            changes[name] = tuple(_float(part, what) for part in _names(text))
        elif isinstance(default, int):
            changes[name] = _whole(text, what)
        else:
            changes[name] = _float(text, what)
    return kind(**changes)


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
            name: _whole(value, f"--latency {name}", " of samples")
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
        structure=args.structure,
        start_seed=args.start_seed,
        screen_start=not args.start_as_given,
        max_iterations=args.max_iterations,
        step_tol=args.step_tol,
        defect_tol=args.defect_tol,
        identifiability_threshold=args.identifiability_threshold,
        max_misfit=args.max_misfit,
        uncertainty=args.uncertainty,
        consider_method=args.consider_method,
        gauss_newton=_settings(GaussNewtonSettings, args.gauss_newton, "--gauss-newton"),
        strategy=_settings(StrategySettings, args.strategy, "--strategy"),
        verbose=0 if args.quiet else 1,
        **extra,
    )
