"""Values the ``nbs`` commands read from their command lines, parsed in one place: among them the
robot's options, one argument group that ``nbs scan``, ``nbs compare`` and ``nbs train`` share."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "MAX_RUNS",
    "add_robot_arguments",
    "add_scene_arguments",
    "adopt_requirements",
    "config_from_arguments",
    "integer_from",
    "parse_range",
    "scene_option_error",
    "scene_options",
]


#: The most values a range option may span, and the most runs one grid may hold: ``generated:A-B``
#: is expanded into one scene per seed, and ``generated:0-100000000000`` once ran out of memory building
#: the list. 100,000 runs of the fastest preset take days on a workstation, far beyond any study here
#: (the test storeys are 20, the corpus 20), while the list of them takes a few megabytes.
MAX_RUNS = 100_000


def parse_range(text: str, most: int = MAX_RUNS) -> tuple[int, int]:
    """``"A-B"`` → ``(A, B)`` and ``"A"`` → ``(A, A)``, for integers 0 <= A <= B.

    Parameters
    ----------
    text : str
        ``"A-B"`` or ``"A"``.
    most : int
        The most values the range may span (``B - A + 1``), checked before anything is made of it
        (default :data:`MAX_RUNS`).

    Returns
    -------
    (int, int)

    Raises
    ------
    ValueError
        Anything else, or a range of more than ``most`` values, with a message that quotes ``text``.
    """
    from nbs_env.config.checks import parse_int

    lo, sep, hi = str(text).strip().partition("-")
    try:
        a = parse_int(lo)
        b = parse_int(hi) if sep else a
    except ValueError:
        raise ValueError(f"expected N or A-B with integers 0 <= A <= B, got {text!r}") from None
    if a < 0 or b < a:
        raise ValueError(f"expected N or A-B with integers 0 <= A <= B, got {text!r}")
    if b - a + 1 > most:
        raise ValueError(f"{text!r} spans {b - a + 1:,} values, at most {most:,}")
    return a, b


# ---------------------------------------------------------------------- the robot's options
#: :data:`nbs_env.config.PRESETS`' names, written out so that ``--help`` loads no configuration
#: (tests/test_cli.py checks them against the presets).
PRESET_NAMES = ("default", "paper", "fast", "train")
WALL_SEARCH_HELP = (
    "search scans per room (rooms.wall_search.scans): before a room ends, scan from where most of its "
    "wall that no scan faced is seen, so that doors there can be found (default: the preset's, 3; 0: the paper's "
    "method, as --preset paper)"
)
STOREY_HELP = (
    "the IFC storey, by name (Name or LongName) or index in the storeys sorted by elevation (0 the lowest, -1 the "
    "highest); a storey named exactly as given wins over the index, so --storey 1 is the storey named '1' where "
    "there is one (IFC files only)"
)
IFC_DOORS_HELP = "IFC doors open (frames only, the default) or closed (as drawn); IFC files only"
#: :data:`scenes.limits.UNITS`' names, written out so that ``--help`` loads no scene code
#: (tests/test_bad_input.py checks them against the units).
UNIT_NAMES = ("m", "cm", "mm", "ft", "in")
UNITS_HELP = (
    "the unit of the mesh coordinates, scaled to metres (default m); labelled meshes only: IFC files carry "
    "their own units and floor plans are metres"
)
#: The flag that sets a configuration path, for messages that name what a user typed.
FLAGS = {
    "rooms.wall_search.scans": "--wall-search",
    "max_scans": "--max-scans",
    "robot.voxel_size": "--voxel",
    "robot.scanner": "--scanner",
    "robot.scanner.angular_step": "--resolution",
    "quality.min_density": "--min-density",
    "quality.max_incidence": "--max-incidence",
}


def _number(text: str) -> float:
    from nbs_env.config.checks import parse_float

    try:
        value = parse_float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    return value  # its range, finiteness included, is the configuration's to check, by the field's name


def whole(text: str) -> int:
    """An argparse type: an integer in ASCII digits (its range is the configuration's to check)."""
    from nbs_env.config.checks import parse_int

    try:
        return parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def number(text: str) -> float:
    """An argparse type: a decimal number in ASCII (its range is the configuration's to check)."""
    return _number(text)


def integer_from(least: int, what: str = "expected an integer", digits: int | None = None):
    """An argparse type: an integer of at least ``least`` (and of at most ``digits`` digits);
    ``what`` begins the message."""

    def parse(text: str) -> int:
        from nbs_env.config.checks import parse_int

        try:
            value = parse_int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"{what} >= {least}, got {text!r}")
        if digits is not None and abs(value) >= 10**digits:
            raise argparse.ArgumentTypeError(f"{what} of at most {digits} digits, got {text.strip()[:40]}...")
        return value

    return parse


def seed_number(text: str) -> int:
    """An argparse type: a seed, an integer >= 0 of at most :data:`scenes.limits.MAX_SEED_DIGITS`
    digits (a run's folder is named by it)."""
    from scenes.limits import MAX_SEED_DIGITS  # here, not at the top: `nbs --help` loads no scenes

    return integer_from(0, "a seed is an integer", digits=MAX_SEED_DIGITS)(text)


def storey_name(text: str) -> str:
    """``--storey``: the text as typed. Whether ``"1"`` is a name or an index is the file's to say: a
    storey named exactly so wins, else an integer is an index (:func:`scenes.ifc.load_ifc_scene`), so
    the option keeps the text rather than deciding here without the file's storeys.

    Raises
    ------
    argparse.ArgumentTypeError
        An empty name.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a storey name or index, got an empty string")
    return text


def _assignment(text: str) -> tuple[str, Any]:
    """``--set KEY=VALUE``: the value as JSON, else the bare word as a string.

    The JSON is read with its nesting bounded (:func:`scenes.jsonio.read_json`): Python's decoder
    recurses once per level, and a value nested some thousand levels deep ended in a RecursionError.

    Raises
    ------
    argparse.ArgumentTypeError
        No ``=`` or no key, a value nested deeper than :data:`scenes.jsonio.MAX_JSON_DEPTH` levels, or
        an integer beyond a float's range.
    """
    key, eq, value = text.partition("=")
    if not eq or not key.strip():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE (e.g. rooms.completion_fraction=0.05), got {text!r}")
    from scenes.jsonio import MAX_JSON_DEPTH, JSONDuplicateKeyError, JSONNestingError, JSONNumberError, read_json

    try:
        parsed = read_json(value)
    except JSONNestingError:
        raise argparse.ArgumentTypeError(
            f"{key.strip()}: the value nests arrays or objects deeper than {MAX_JSON_DEPTH} levels, "
            f"the most --set reads"
        ) from None
    except JSONNumberError as exc:  # digits, not a word: "must be an integer, got '999...'" misled
        raise argparse.ArgumentTypeError(f"{key.strip()}: the value holds {exc.msg}") from None
    except JSONDuplicateKeyError as exc:  # an object, not a word: "must be a JSON object" misled
        raise argparse.ArgumentTypeError(f"{key.strip()}: {exc.msg}") from None
    except ValueError:
        parsed = value  # a bare word: a string
    return key.strip(), parsed


def _scanner_help() -> str:
    from nbs_env.config.scanners import SCANNERS

    return ", ".join(f"{name} ({', '.join(s.name for s in model.settings)})" for name, model in SCANNERS.items())


def add_scene_arguments(parser: argparse.ArgumentParser | Any) -> None:
    """``--storey``, ``--ifc-doors``, ``--y-up`` and ``--units``: how a building file is read."""
    parser.add_argument(
        "--storey",
        type=storey_name,
        default=None,
        metavar="NAME|INDEX",
        help=STOREY_HELP,
    )
    parser.add_argument("--ifc-doors", choices=("open", "closed"), default=None, help=IFC_DOORS_HELP)
    parser.add_argument(
        "--y-up", action="store_true", help="mesh coordinates are y-up (glTF convention); labelled meshes only"
    )
    parser.add_argument("--units", choices=UNIT_NAMES, default=None, help=UNITS_HELP)


def add_robot_arguments(parser: argparse.ArgumentParser, presets: Sequence[str] = PRESET_NAMES) -> None:
    """The options of every command that runs a robot (``nbs scan``, ``nbs compare``, ``nbs train``),
    in one group with one meaning; :func:`config_from_arguments` reads them."""
    group = parser.add_argument_group(
        "robot and building", "the same on nbs scan, nbs compare and nbs train; metrics.json records the result"
    )
    group.add_argument("--preset", choices=tuple(presets), default=None, help="configuration preset")
    group.add_argument(
        "--scanner",
        default=None,
        metavar="NAME[:SETTING]",
        help="a scanner from its datasheet: " + _scanner_help() + " (default: METHOD's simulated VZ-400)",
    )
    group.add_argument(
        "--resolution", type=_number, default=None, help="simulated angular step in degrees (default 0.5, fast 1)"
    )
    group.add_argument("--voxel", type=_number, default=None, help="voxel size of V(t) in metres (default 0.05)")
    group.add_argument("--wall-search", type=integer_from(0), default=None, metavar="N", help=WALL_SEARCH_HELP)
    group.add_argument("--max-scans", type=integer_from(1), default=None, help="scan budget of an episode")
    group.add_argument("--min-density", type=_number, default=None, help="quality: least points per m² (default 400)")
    group.add_argument(
        "--max-incidence", type=_number, default=None, help="quality: largest incidence angle in degrees (default 70)"
    )
    group.add_argument(
        "--set",
        type=_assignment,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any configuration field by its dotted name, the value as JSON (repeatable; e.g. "
        "--set rooms.completion_fraction=0.05; docs/environment.md lists the names)",
    )
    add_scene_arguments(group)


def scene_options(args: argparse.Namespace) -> dict[str, Any]:
    """The ``load_scene`` options of ``--storey``, ``--ifc-doors``, ``--y-up`` and ``--units`` (only those
    given)."""
    options: dict[str, Any] = {}
    if getattr(args, "storey", None) is not None:
        options["storey"] = args.storey
    if getattr(args, "ifc_doors", None) is not None:
        options["doors"] = args.ifc_doors
    if getattr(args, "y_up", False):
        options["y_up"] = True
    if getattr(args, "units", None) is not None:
        options["units"] = args.units
    return options


def config_from_arguments(
    args: argparse.Namespace, preset: str, measured: bool = True, **defaults: Any
) -> tuple[str, dict[str, Any]]:
    """The preset and the dotted configuration overrides the robot options of a command line give.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by a parser with :func:`add_robot_arguments`.
    preset : str
        The command's preset when ``--preset`` is not given.
    measured : bool
        The command reports the true coverage (``nbs scan``, ``nbs compare``): a configuration
        without the coverage meter (the ``train`` preset) is refused.
    **defaults
        The command's own defaults of configuration paths (``max_scans=80``), used when no option
        sets them.

    Returns
    -------
    preset : str
    overrides : dict
        Dotted configuration names to values, for :func:`nbs_env.config.make_config`: only what the
        command line (or the command's defaults) set, so that what a policy requires may fill the
        rest.

    Raises
    ------
    ConfigError
        A bad scanner name, a ``--set`` name the configuration has not, or two options setting one
        field; the message names the options.
    """
    from nbs_env.config import make_config
    from nbs_env.config.presets import config_paths
    from nbs_env.errors import ConfigError

    preset = args.preset or preset
    given: dict[str, Any] = {}
    if args.scanner is not None:
        from nbs_env.config.scanners import scanner_config

        scanner = make_config(preset).robot.scanner  # the preset's simulated step and height stay
        step = scanner.angular_step if args.resolution is None else args.resolution
        given["robot.scanner"] = scanner_config(args.scanner, simulated_step=step, height=scanner.height).to_dict()
    elif args.resolution is not None:
        given["robot.scanner.angular_step"] = args.resolution
    flags = {
        "robot.voxel_size": args.voxel,
        "rooms.wall_search.scans": args.wall_search,
        "max_scans": args.max_scans,
        "quality.min_density": args.min_density,
        "quality.max_incidence": args.max_incidence,
    }
    given.update({k: v for k, v in flags.items() if v is not None})
    options = scene_options(args)
    if options:
        given["scene_options"] = options
    paths = config_paths()
    by_set: set[str] = set()  # the fields --set has set, told apart from the options' in a clash
    for key, value in args.set:
        root = key.split(".", 1)[0]
        if root in COMMAND_FIELDS:
            raise ConfigError(f"--set {key}: {COMMAND_FIELDS[root]}")
        if key not in paths:
            full = [p for p in paths if p.rpartition(".")[2] == key]
            if full:  # make_config takes a field's own name; --set names the field whole
                raise ConfigError(f"--set {key}: give the field's dotted name ({' or '.join(full[:3])})")
            raise ConfigError(f"--set {key}: the configuration has no such field (dotted names, e.g. robot.voxel_size)")
        if key in by_set:
            raise ConfigError(f"--set {key} is given twice; give each field once")
        if args.scanner is not None and key.startswith("robot.scanner."):
            # A field of the --scanner's scanner: the height is the user's, and a datasheet value set
            # here is refused by the configuration's check unless robot.scanner.preset is set to null.
            if key == "robot.scanner.angular_step" and args.resolution is not None:
                raise ConfigError(f"--set {key} and --resolution both set {key}")
            given["robot.scanner"] = {**given["robot.scanner"], key.rsplit(".", 1)[1]: value}
            by_set.add(key)
            continue
        clash = [p for p in given if p == key or p.startswith(key + ".") or key.startswith(p + ".")]
        if clash:
            other = f"--set {clash[0]}" if clash[0] in by_set else FLAGS.get(clash[0], clash[0])
            raise ConfigError(f"--set {key} and {other} both set {key}")
        given[key] = value
        by_set.add(key)
    for key, value in defaults.items():
        given.setdefault(key, value)
    config = make_config(preset, **given)  # checked now, before any work starts
    if measured and not config.coverage_meter:
        raise ConfigError(
            f"--preset {preset} runs no coverage meter (nbs train's training fidelity), and this command reports "
            "coverage: use --preset fast, the same robot with the meter"
        )
    return preset, given


#: Configuration fields a command sets itself, with what to use instead of ``--set``.
COMMAND_FIELDS = {
    "scene": "the command's --scene (nbs compare: --scenes) names the building",
    "scene_options": "--storey, --ifc-doors, --y-up and --units say how the building file is read",
    "preset": "use --preset",
    "keep_scans": "the command decides whether the scans are kept (nbs scan keeps them for scans.e57)",
}


def adopt_requirements(overrides: dict[str, Any], requirements: dict[str, tuple[Any, str]]) -> dict[str, Any]:
    """``overrides`` with what the policies require added where the command line set nothing.

    Parameters
    ----------
    overrides : dict
        :func:`config_from_arguments`'s overrides.
    requirements : dict
        Path -> (value, the policy that requires it), from :func:`policies.agreed_requirements`.

    Raises
    ------
    ConfigError
        The command line set a required field to another value; the message names the policy, the
        value it requires and the option that sets it.
    """
    from nbs_env.config import json_form
    from nbs_env.errors import ConfigError

    out = dict(overrides)
    for path, (value, who) in requirements.items():
        if path in out and json_form(out[path]) != json_form(value):
            # A flag takes its value after a space; --set takes KEY=VALUE as one word.
            given = f"{FLAGS[path]} {json.dumps(value)}" if path in FLAGS else f"--set {path}={json.dumps(value)}"
            raise ConfigError(
                f"{who} requires {path}={json.dumps(value)} (it was trained so), but this run sets "
                f"{json.dumps(out[path])}: pass {given} or leave it out"
            )
        out[path] = value
    return out


#: Scene files by kind, for the options that apply to one kind only.
MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply")


def scene_option_error(
    scene: str, storey: object, y_up: bool, ifc_doors: object = None, units: object = None, flag: str = "--scene"
) -> str | None:
    """Why ``--storey``, ``--ifc-doors``, ``--y-up`` or ``--units`` does not apply to ``scene`` (None when
    they do).

    A corpus entry (``corpus:NAME``) carries its own options; only IFC's apply to it. A name that is
    not valid UTF-8 is refused too: the reports, clouds and pictures carry it. ``flag`` is how the
    command takes the scene ("" for a positional argument)."""
    from train.outputs import utf8_problem

    problem = utf8_problem(flag, scene)
    if problem is not None:
        return problem
    suffix = Path(scene).suffix.lower()
    ifc = suffix == ".ifc" or _corpus_suffix(scene) == ".ifc"
    if storey is not None and not ifc:
        return f"--storey applies to .ifc files only, not to scene {scene!r}"
    if ifc_doors is not None and not ifc:
        return f"--ifc-doors applies to .ifc files only, not to scene {scene!r}"
    if (y_up or units is not None) and _corpus_suffix(scene) in MESH_SUFFIXES:
        return (
            f"{'--y-up' if y_up else '--units'}: {scene} is read with its corpus entry's own options "
            "(scenes/data/corpus/corpus.json); to read its mesh otherwise, name the mesh file itself"
        )
    if y_up and suffix not in MESH_SUFFIXES:
        return f"--y-up applies to labelled meshes ({', '.join(MESH_SUFFIXES)}) only, not to scene {scene!r}"
    if units is not None and suffix not in MESH_SUFFIXES:
        return (
            f"--units applies to labelled meshes ({', '.join(MESH_SUFFIXES)}) only, not to scene {scene!r} "
            "(IFC files carry their own units, floor plans are metres)"
        )
    return None


def _corpus_suffix(scene: str) -> str | None:
    """The file suffix of corpus entry ``scene`` (None when it is no corpus entry or has no file)."""
    if not str(scene).startswith("corpus:"):
        return None
    from scenes import SceneError
    from scenes.corpus import corpus_entry

    try:
        entry = corpus_entry(str(scene)[len("corpus:") :])
    except SceneError:
        return None
    return Path(entry.file).suffix.lower() if entry.file else None
