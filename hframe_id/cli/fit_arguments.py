"""The arguments of ``hframe-id fit`` (``fit_command`` registers the subcommand with them and
runs it): the recordings and start, the free parameters and bounds, the noise, the
transcription, the strategy, convergence, statistics and outputs, each group in its own
function."""

from __future__ import annotations

import argparse

from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import output_folder
from hframe_id.fitting.link_options import CONSIDER_METHODS, CONTINUITY, UNCERTAINTY_METHODS
from hframe_id.fitting.options import NOISE_METHODS, STRUCTURES, FitOptions
from hframe_id.fitting.solvers import solver_names

#: Most fits a multistart portfolio may run (``--starts``): each is a whole fit (2-5 s on a
#: shipped recording); 100000 ran for hours.
MAX_STARTS = 100
#: Most Gauss-Newton iterations per stage (``--max-iterations``, default 150): a stage that
#: does not converge runs all of them.
MAX_ITERATIONS = 10_000


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except empty ones and flags (their help says what happens)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default in (None, "", [], ()) or isinstance(action.default, bool):
            return action.help or ""
        return super()._get_help_string(action)


def add_fit_arguments(parser: argparse.ArgumentParser) -> None:
    """Every argument of ``hframe-id fit``, group by group."""
    _add_data_options(parser)
    _add_parameter_options(parser)
    _add_noise_options(parser)
    _add_transcription_options(parser)
    _add_strategy_options(parser)
    _add_convergence_options(parser)
    _add_statistics_options(parser)
    _add_output_options(parser)


def _add_data_options(parser: argparse.ArgumentParser) -> None:
    """The recordings and the start: ``files``, ``--initial``, ``--model``."""
    parser.add_argument(
        "files",
        nargs="+",
        metavar="FILE",
        help="MCAP recordings; a bare name is looked up in ./datasets/, then in the "
        "project's shipped datasets/",
    )
    parser.add_argument(
        "--initial",
        metavar="FILE",
        help="initial parameter file (default: the model's reference set, for the thesis's "
        "variants their table: one-axis: models/one-axis-table2.3.yaml, hframe-20: "
        "models/hframe-20-table3.1.yaml, hframe-8: models/hframe-8-table4.2.yaml)",
    )
    parser.add_argument(
        "--model",
        metavar="VARIANT",
        help="model variant to fit (one-axis, hframe-20, hframe-8, any `hframe-id models` "
        "lists, or one from --model-file; default: "
        "the model of the --model-file, else the recordings' rig variant); picks the default "
        "initial file",
    )


def _add_parameter_options(parser: argparse.ArgumentParser) -> None:
    """Which parameters are free and their bounds [SI units]."""
    parser.add_argument(
        "--free",
        metavar="NAMES",
        help="comma-separated parameter names or patterns to fit (e.g. 'k_*,J_M*'); default: "
        "every stiffness, mass, inertia, viscous and Coulomb friction parameter and g_2; "
        "'default' names that set (e.g. 'default,I_max' frees one more)",
    )
    parser.add_argument(
        "--fix",
        metavar="NAMES",
        default="",
        help="comma-separated names or patterns to hold at their initial value",
    )
    parser.add_argument(
        "--bounds",
        metavar="NAME=LOW:HIGH",
        action="append",
        default=[],
        help="bounds of a free parameter (exact name, not a pattern) in SI units, both "
        "positive (parameters are fitted in log scale) and enclosing the initial value "
        "(repeatable)",
    )
    add_number(
        parser,
        "--bound-factor",
        float,
        above=1,
        default=10.0,
        help="default bounds: initial value divided / multiplied by this",
    )


def _add_noise_options(parser: argparse.ArgumentParser) -> None:
    """How the residuals are weighted: the channels' noise std [rad or m]."""
    parser.add_argument(
        "--channel-std",
        metavar="OUTPUT=STD",
        action="append",
        default=[],
        help="noise std [rad or m] that weights an output's residuals (repeatable; outputs "
        "phi1, phi2, x, y for the H-frame, phi1, x for one-axis); default: "
        "encoder step/sqrt(12) and the rig's laser noise",
    )
    parser.add_argument(
        "--noise",
        choices=NOISE_METHODS,
        default=FitOptions.noise,
        help="channel weights: 'sensor' the sensors' noise (--channel-std or the rig's "
        "noise model); 'estimate' noise levels estimated from the residuals; 'auto' "
        "estimated when the model does not follow the data at the sensors' noise level",
    )


def _add_transcription_options(parser: argparse.ArgumentParser) -> None:
    """The solver of the all-window stages and the transcription it solves: sensor latency
    [samples], shooting intervals [samples], continuity, Coulomb smoothing, initial states."""
    parser.add_argument(
        "--solver",
        choices=solver_names(),
        default=FitOptions.solver,
        help="solver of the all-window stages: the condensed Gauss-Newton, or CasADi's "
        "IPOPT or SQP (nlpsol, exact Gauss-Newton Hessian) on the same transcription",
    )
    parser.add_argument(
        "--latency",
        action="append",
        default=[],
        metavar="OUTPUT=SAMPLES",
        help="whole samples a sensor lags the plant (repeatable, e.g. x=2 for a laser with "
        "2 ms read-out latency at 1 kHz); not estimated: in steady motion it looks like "
        "belt stretch",
    )
    add_number(
        parser,
        "--shooting-interval",
        int,
        at_least=1,
        metavar="SAMPLES",
        help="samples per shooting interval (a node every this many samples; default: the "
        "model's fit default, else 10)",
    )
    parser.add_argument(
        "--continuity",
        choices=CONTINUITY,
        help="'exact': the intervals join into one simulated trajectory (output error); "
        "'none': each interval starts from its own estimated state (prediction error on "
        "horizons of --shooting-interval samples, for plants whose simulation drifts). "
        "Default: the model's fit default, else 'exact'",
    )
    parser.add_argument(
        "--smoothing",
        metavar="LIN,ANG",
        help="final Coulomb smoothing velocities [m/s],[rad/s] (default: the model's 1e-3,1e-2)",
    )
    parser.add_argument(
        "--smoothing-schedule",
        metavar="F1,F2,...",
        default="1",
        help="continuation factors on the smoothing, decreasing to 1, applied in the "
        "moving-window stages; the default 1 is no continuation (measured worse on these "
        "records, docs/fitting.md)",
    )
    parser.add_argument(
        "--initial-state",
        choices=("auto", "rest", "estimate"),
        default="auto",
        help="each recording's initial state: at rest (every velocity zero and the belts "
        "unstretched, at the measured position, as validate and simulate start; the stages "
        "estimate the belt-free position, a last solve takes validate's) where "
        "the record's first 10 samples show rest, estimated where it starts in motion (auto); "
        "every one at rest; or every one estimated",
    )


def _add_strategy_options(parser: argparse.ArgumentParser) -> None:
    """The stages: zero-reachable friction, known points, the multistart portfolio, the start,
    the structure."""
    parser.add_argument(
        "--structure",
        choices=STRUCTURES,
        default=FitOptions.structure,
        help="'choose' (default): a model that nests in a larger one (hframe-8 in "
        "hframe-8-current-limit, amplifiers limiting current to I_max) is fitted as that one "
        "too, I_max free, and the larger kept where it replays the records better by the 95 "
        "%% likelihood ratio with I_max determined (the written file is then of that "
        "variant); 'as-given': the start's model only",
    )
    parser.add_argument(
        "--zero-reachable",
        default="",
        metavar="NAMES",
        help="comma-separated friction parameters fitted linearly from 0, which they may "
        "reach (the others are fitted in log scale, and a fit that ends with one on its lower "
        "bound is repeated with it reaching 0)",
    )
    parser.add_argument(
        "--known",
        action="append",
        default=[],
        metavar="FILE",
        help="a parameter file of the fitted model the fit must not end worse than (besides "
        "its start, the equation-error estimate and the model's reference files): ended "
        "worse, it continues from the best of them, or fails saying so; repeatable",
    )
    add_number(
        parser,
        "--starts",
        int,
        at_least=1,
        at_most=MAX_STARTS,
        default=FitOptions.starts,
        metavar="N",
        help="a multistart portfolio: the fit from the start and from N-1 seeded draws "
        "around it (each free parameter x/÷2 at most), the best kept and how many starts "
        "reached it reported (default 1: the start only); N fits' time",
    )
    add_number(
        parser,
        "--start-seed",
        int,
        at_least=0,
        default=FitOptions.start_seed,
        metavar="S",
        help="seed of the portfolio's draws (default 0)",
    )
    parser.add_argument(
        "--start-as-given",
        action="store_true",
        help="begin from --initial even where the model's reference files or a --known file "
        "simulate the records (all starting at rest) better (default: from the best of them, "
        "said in the summary)",
    )
    parser.add_argument(
        "--no-first-stage",
        action="store_true",
        help="skip the equation-error start and the stages on the moving windows (start the "
        "full multiple-shooting problem directly from --initial)",
    )


def _add_convergence_options(parser: argparse.ArgumentParser) -> None:
    """When a stage has converged: iterations, step and defect tolerances; the tuning of the
    Gauss-Newton iteration and of the stages."""
    parser.add_argument(
        "--gauss-newton",
        action="append",
        default=[],
        metavar="SETTING=VALUE",
        help="a setting of the Gauss-Newton iteration (repeatable; GaussNewtonSettings in "
        "docs/api.md: trust region, node damping, watchdog, stall rules), recorded in the "
        "parameter file's provenance",
    )
    parser.add_argument(
        "--strategy",
        action="append",
        default=[],
        metavar="SETTING=VALUE",
        help="a setting of the stages (repeatable; StrategySettings in docs/api.md: "
        "intermediate tolerances, noise rounds, box widenings, restarts, holds; a tuple as "
        "comma-separated numbers), recorded in the parameter file's provenance",
    )
    add_number(
        parser,
        "--max-iterations",
        int,
        at_least=1,
        at_most=MAX_ITERATIONS,
        default=FitOptions.max_iterations,
        help="Gauss-Newton iterations per stage",
    )
    add_number(
        parser,
        "--step-tol",
        float,
        above=0,
        default=1e-6,
        help="converged when no parameter changes by more than this (relative)",
    )
    add_number(
        parser,
        "--defect-tol",
        float,
        above=0,
        default=1e-2,
        help="continuity defects at convergence, in noise units; a stage that can no "
        "longer decrease its cost is also accepted with defects below 2 noise std if the "
        "residuals are at the noise level (rms <= 1.5 std), and the largest defect is "
        "reported in the solver message",
    )


def _add_statistics_options(parser: argparse.ArgumentParser) -> None:
    """Identifiability, the misfit limit [noise std] and how standard errors are computed."""
    add_number(
        parser,
        "--identifiability-threshold",
        float,
        above=0,
        default=0.1,
        help="relative std error above which a parameter counts as not "
        "identified and is held at its initial value",
    )
    add_number(
        parser,
        "--max-misfit",
        float,
        above=0,
        default=None,
        help="a fit whose residual rms exceeds this many std of the sensors' noise (the "
        "rig's specification or --channel-std, never a level estimated from the residuals) "
        "fails (default: 5 for a fit weighted by the sensors' noise, no limit for one that "
        "estimated its noise levels under model mismatch)",
    )
    parser.add_argument(
        "--uncertainty",
        choices=UNCERTAINTY_METHODS,
        default="robust",
        help="how standard errors are computed",
    )
    parser.add_argument(
        "--consider-method",
        choices=CONSIDER_METHODS,
        default=FitOptions.consider_method,
        help="how the held parameters' prior uncertainty (+/-20 %%) enters: 'linear' (held, "
        "the intervals widened at the optimum), 'refit' (held, the fit repeated twice per held "
        "parameter at its value x exp(+/-0.2): slower, for effects that are not linear) or "
        "'prior' (estimated, with the prior as a penalty: maximum a posteriori)",
    )


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    """Threads, cross-validation and what is written where (files, stderr, JSON on stdout)."""
    add_number(
        parser,
        "--threads",
        int,
        at_least=1,
        default=None,
        help="worker threads (default: the CPU count, at most 8)",
    )
    parser.add_argument(
        "--no-cross-validation",
        action="store_true",
        help="skip the leave-one-recording-out cross-validation of a fit of several "
        "recordings (it refits once per recording)",
    )
    parser.add_argument(
        "--out-dir",
        type=output_folder("--out-dir"),
        default="fits",
        help="where the fit and report go",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument(
        "--no-plots", action="store_true", help="write the report without its figures (faster)"
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout (success, fit id, files, every parameter with "
        "unit, std and 95 %% interval; docs/fitting-json.md); the summary goes to stderr",
    )
