"""The house rules: imports run one way (scenes -> nbs_env -> policies -> train), and the code is lint-clean."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ["scenes", "nbs_env", "policies", "train"]


def imported_packages(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


@pytest.mark.parametrize("floor", FLOORS)
def test_nothing_imports_upward(floor):
    above = set(FLOORS[FLOORS.index(floor) + 1 :])
    offenders = {}
    for path in (ROOT / floor).rglob("*.py"):
        bad = imported_packages(path) & above
        if bad:
            offenders[str(path.relative_to(ROOT))] = sorted(bad)
    assert not offenders, f"{floor} imports from a floor above it: {offenders}"


def test_scenes_has_no_gymnasium_or_robot_imports():
    for path in (ROOT / "scenes").rglob("*.py"):
        assert "gymnasium" not in imported_packages(path), path


def test_ruff_is_clean():
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed (it is in the 'test' extra)")
    proc = subprocess.run([ruff, "check", "--no-cache", str(ROOT)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


#: The one documented reader of ground truth among the policies: the yardstick, not a competitor.
ORACLE = ROOT / "policies" / "oracle.py"
#: Modules of scenes that hold no building, which perception and the policies may import.
NO_BUILDING = {"scenes._open3d", "scenes.errors", "scenes.jsonio", "scenes.memory"}


def test_perception_and_policies_never_import_ground_truth():
    """Honest simulation: perception and the policies see measured points only, so they never import
    the scene model; the oracle is the one named exception."""
    for folder in (ROOT / "nbs_env" / "perception", ROOT / "nbs_env" / "mapping", ROOT / "nbs_env" / "planning",
                   ROOT / "policies"):  # fmt: skip
        for path in folder.rglob("*.py"):
            if path == ORACLE:
                continue
            modules = _full_modules(path)
            # scenes._open3d only loads open3d (with its libusb), scenes.jsonio reads JSON with bounded
            # nesting (a checkpoint's description), scenes.errors holds exception classes and the
            # cutting of long names in messages, scenes.memory reads the memory left; none holds a building.
            offenders = {m for m in modules if m.split(".")[0] == "scenes" and m not in NO_BUILDING}
            assert not offenders, f"{path} imports {offenders} (ground truth)"


#: The robot's pipeline, in order: each subpackage of nbs_env may import only those before it.
PIPELINE = ["sensing", "perception", "mapping", "planning"]


def test_the_pipeline_imports_only_backwards():
    """sensing -> perception -> mapping -> planning: no import of a later stage, not in a function
    body, not under ``if TYPE_CHECKING:`` (registration reads S(t) through a Protocol of its own)."""
    for k, stage in enumerate(PIPELINE):
        later = {f"nbs_env.{name}" for name in PIPELINE[k + 1 :]}
        for path in (ROOT / "nbs_env" / stage).rglob("*.py"):
            offenders = {m for m in _full_modules(path) if any(m == p or m.startswith(p + ".") for p in later)}
            assert not offenders, f"{path.relative_to(ROOT)} imports {sorted(offenders)}, a later stage"


def test_the_meter_knows_no_storey():
    """The coverage meter is the storey's (storey -> evaluation): evaluation.py imports neither the
    storey session nor the report that reads it, not even under ``if TYPE_CHECKING:``."""
    modules = _full_modules(ROOT / "nbs_env" / "evaluation.py")
    assert not modules & {"nbs_env.storey", "nbs_env.report", "nbs_env.export"}, sorted(modules)


def test_the_oracle_is_imported_only_by_the_comparison():
    """No policy that competes may consult the oracle (it reads the true building)."""
    for path in (ROOT / "policies").rglob("*.py"):
        if path != ORACLE:
            assert "oracle" not in {a for a in _imported_modules(path)}, f"{path} imports the oracle"


def _full_modules(path: Path, runtime_only: bool = False) -> set[str]:
    """The modules ``path`` imports by absolute name; ``runtime_only`` leaves out those under
    ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text())
    typing_only = set()
    if runtime_only:
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
                typing_only |= {id(n) for n in ast.walk(node)}
    out = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
    return out


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            out |= set(node.module.split("."))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                out |= set(alias.name.split("."))
    return out


# ---------------------------------------------------------------------- one step, top-down
#: The modules one NBSEnv.step passes through, top to bottom: each may import only those below it.
STEP_LAYERS = [
    "nbs_env/env.py",
    "nbs_env/storey.py",
    "nbs_env/robot.py",
    "nbs_env/planning/rooms.py",
    "nbs_env/planning/planner.py",
    "nbs_env/belief.py",
]


def _runtime_nbs_imports(path: Path) -> set[str]:
    """nbs_env modules ``path`` imports at run time (imports under ``if TYPE_CHECKING:`` left out)."""
    return {m for m in _full_modules(path, runtime_only=True) if m.split(".")[0] == "nbs_env"}


def _module_path(module: str) -> str:
    return module.replace(".", "/") + ".py"


def test_a_step_reads_top_down():
    """env → storey → robot → rooms → planner → belief: nothing lower imports a module above it."""
    for k, name in enumerate(STEP_LAYERS):
        above = set(STEP_LAYERS[:k])
        imported = {_module_path(m) for m in _runtime_nbs_imports(ROOT / name)}
        assert not imported & above, f"{name} imports {sorted(imported & above)}, which call it"


def test_the_env_talks_to_the_storey_only():
    """The env never reaches into the robot, its belief or the planner: it reads the storey session,
    the belief view and the configuration."""
    allowed = {"nbs_env.errors", "nbs_env.observation", "nbs_env.config", "nbs_env.storey", "nbs_env.render"}
    path = ROOT / "nbs_env" / "env.py"
    assert _runtime_nbs_imports(path) <= allowed
    tree = ast.parse(path.read_text())
    reached = {
        node.attr
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and node.attr in {"robot", "belief", "meter"}
        and not (isinstance(node.value, ast.Name) and node.value.id == "config")
    }
    assert not reached, f"nbs_env/env.py reaches into {sorted(reached)}"


def test_scenes_knows_no_robot_and_the_footprints_agree():
    """scenes promises a clearance (STOREY_CLEARANCE); the robot's footprint is nbs_env's, and its
    defaults need exactly that clearance and fit the narrowest valid door."""
    from nbs_env.planning.navigation import NavigationConfig
    from scenes.geometry import STOREY_CLEARANCE
    from scenes.validation import MIN_DOOR_WIDTH

    nav = NavigationConfig()
    assert nav.required_clearance == pytest.approx(STOREY_CLEARANCE)
    assert 2 * nav.robot_radius < MIN_DOOR_WIDTH
    for path in (ROOT / "scenes").rglob("*.py"):
        text = path.read_text()
        assert "ROBOT_RADIUS" not in text and "SAFETY_DISTANCE" not in text, path


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _all_imports(path: Path) -> set[str]:
    """Every module ``path`` imports, wherever the import stands (module top, a function body,
    ``if TYPE_CHECKING:``), by absolute name; ``from package import name`` also names
    ``package.name``, which is a module when it is one."""
    tree = ast.parse(path.read_text())
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                module = base + (f".{node.module}" if node.module else "")
            else:
                module = node.module or ""
            out.add(module)
            out |= {f"{module}.{alias.name}" for alias in node.names}
        elif isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
    return out


def _import_graph() -> dict[str, set[str]]:
    """Module -> the modules of the same floor it imports (a package's ``__init__`` counts as the
    package's module)."""
    files = {_module_name(p): p for floor in FLOORS for p in (ROOT / floor).rglob("*.py")}
    graph = {}
    for name, path in files.items():
        deps = set()
        for module in _all_imports(path):
            while module and module not in files:
                module = module.rpartition(".")[0]
            if module and module != name and module.split(".")[0] == name.split(".")[0]:
                deps.add(module)
        graph[name] = deps
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    state: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(u: str) -> None:
        state[u] = 1
        stack.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == 1:
                found.append([*stack[stack.index(v) :], v])
            elif v not in state:
                visit(v)
        stack.pop()
        state[u] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name)
    return found


def test_no_import_cycles_between_modules():
    """No module imports, however indirectly, one that imports it: counting imports in function
    bodies and under ``if TYPE_CHECKING:``, and a package's ``__init__`` as a module."""
    found = _cycles(_import_graph())
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_no_import_cycles_between_the_parts_of_nbs_env():
    """nbs_env's parts (its subpackages and top-level modules) import one another one way, and the
    pipeline's subpackages in its order: sensing, perception, mapping, planning."""
    units: dict[str, set[str]] = {}
    for name, deps in _import_graph().items():
        parts = name.split(".")
        if parts[0] != "nbs_env" or len(parts) < 2:
            continue
        units.setdefault(parts[1], set()).update(
            d.split(".")[1] for d in deps if d.count(".") >= 1 and d.split(".")[1] != parts[1]
        )
    found = _cycles(units)
    assert not found, "cycles between nbs_env's parts: " + "; ".join(" -> ".join(c) for c in found)
    order = ["sensing", "perception", "mapping", "planning"]
    for k, part in enumerate(order):
        later = units.get(part, set()) & set(order[k + 1 :])
        assert not later, f"{part} imports {sorted(later)}, which come after it"


def test_the_robot_senses_moves_and_keeps_its_belief():
    """robot.py holds no door memory, route, approach or search: those are the planning side's
    (nbs_env/planning/rooms.py); and nothing outside the belief writes into it."""
    robot = ROOT / "nbs_env" / "robot.py"
    tree = ast.parse(robot.read_text())
    methods = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    words = ("door", "route", "approach", "search", "finish_room")
    planning = {m for m in methods if any(w in m for w in words)}
    assert not planning, f"robot.py plans: {sorted(planning)}"
    imported = _all_imports(robot)
    assert not {m for m in imported if m.startswith(("nbs_env.planning.rooms", "nbs_env.planning.wall_search"))}
    assert "nbs_env.perception.doors" not in imported
    for floor in FLOORS:
        for path in (ROOT / floor).rglob("*.py"):
            if path.name == "belief.py":
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Assign):
                    targets = node.targets
                elif isinstance(node, ast.AugAssign):
                    targets = [node.target]
                else:
                    continue
                for target in targets:
                    inner = target.value if isinstance(target, ast.Attribute) else None
                    assert not (isinstance(inner, ast.Attribute) and inner.attr == "belief"), (
                        f"{path.relative_to(ROOT)}:{node.lineno} writes into the belief"
                    )


def test_one_home_for_each_setting_and_what_policies_need_is_declared():
    """The search count lives in WallSearchConfig alone, and no code asks a policy for an attribute
    the Policy protocol does not declare."""
    for floor in [*FLOORS, "benchmarks"]:
        for path in (ROOT / floor).rglob("*.py"):
            text = path.read_text()
            assert "wall_search_scans" not in text, path
            for attribute in ("robot_overrides", "env_overrides", "config_overrides", "requires"):
                assert f'getattr(policy, "{attribute}"' not in text, (path, attribute)


def test_the_independent_coverage_count_imports_nothing_of_the_project():
    """tests/independent_coverage.py checks the project's figure: it must not share its code."""
    tree = ast.parse((Path(__file__).parent / "independent_coverage.py").read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    ours = {"nbs_env", "scenes", "policies", "train", "tests"}
    assert names and not {n for n in names if n.split(".")[0] in ours}, names
