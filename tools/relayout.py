"""Move manip_kin to its wings (issue 25): one table, ``git mv`` and a rewrite of every reference.

    python tools/relayout.py [--dry-run]

Run from anywhere inside the repository. It is idempotent: a second run changes nothing, so it
can be run again on a tree where other branches were merged after the first run (their files at
old paths are moved, their old imports rewritten). What it does:

1. ``git mv`` each module (or package) of :data:`MODULES` and each test file of :data:`TESTS` that
   still exists at its old path; creates the new packages' ``__init__.py``; removes ``nodes/``
   once it is empty.
2. Rewrites, in every tracked text file (code, tests, bench, tools, docs, README, setup.py,
   ruff.toml, ...): dotted module names (``from manip_kin.x import``, ``import manip_kin.x``,
   ``"manip_kin.x:main"``, ``python -m manip_kin.x``, ``:mod:`manip_kin.x```), file paths
   (``manip_kin/x.py``, ``manip_kin/closed_form/``) and test paths (``test/test_x.py``).
3. Imports of re-exported names (:data:`REEXPORTS`: the ``conversions`` shim, ``rate_loop``'s
   lazy ``LoopingNode``, the names that moved when the modules over 400 lines were split) are
   pointed at the module that defines them, ``conv.x`` becomes ``x``;
   the shim files (:data:`SHIMS`) are deleted. Run ``make format`` afterwards (import order).

The hand edits that need thought (splits, cycles, renames of classes) are separate commits.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

#: Old module (dotted, under ``manip_kin``) -> new module. A package entry moves the whole
#: package; the longest matching entry wins, so ``nodes.cdr`` beats ``nodes``.
MODULES: dict[str, str] = {
    # codegen: the only place that writes Python source
    "kernel_cache": "codegen.kernel_cache",
    "unrolled_linalg": "codegen.unrolled_linalg",
    "source_inline": "codegen.source_inline",
    "chain_codegen": "codegen.chain",
    "fast_step": "codegen.control_step",
    "ik_codegen": "codegen.ik_step",
    # core: the model and what is computed from it directly
    "model": "core.model",
    "model_kernels": "core.model_kernels",
    "rotations": "core.rotations",
    "kinematics": "core.kinematics",
    "plain_floats": "core.plain_floats",
    "loaders": "core.loaders",
    "robots": "core.robots",
    "robot_files": "core.robot_files",
    "urdf": "core.urdf",
    "tf_tree": "core.tf_tree",
    "scene": "core.scene",
    "meshes": "core.mesh_uris",
    "bounds": "core.bounds",
    "damped_least_squares": "core.damped_least_squares",
    "tasks": "core.pose_rows",
    # control: laws, limits, integration, prediction, state machines, offline simulation
    "control": "control.resolved_rate",
    "reference_law": "control.reference_law",
    "joint_control": "control.joint_tracking",
    "joint_integration": "control.integration",
    "joint_limits": "control.joint_limits",
    "command_filter": "control.command_filter",
    "servo": "control.servo",
    "state_prediction": "control.state_prediction",
    "simulation": "control.simulation",
    "supervisors": "control.state_machines",
    "qp": "control.qp",
    # ik: iterative and closed form
    "ik": "ik.iterative",
    "ik_all": "ik.all_solutions",
    "ik_iteration": "ik.iteration",
    "ik_problem": "ik.problem",
    "ik_result": "ik.result",
    "ik_seeds": "ik.seeds",
    "closed_form": "ik.closed_form",
    # motion: lines and joint trajectories
    "trajectory": "motion.lines",
    "joint_trajectory": "motion.joint_trajectory",
    "line_timing": "motion.line_timing",
    # recording: names that clashed with ros.wire's
    "recording.messages": "recording.reader",
    "recording.cdr": "recording.cdr_measure",
    # ros: the wire format, the node runtime, the node programs
    "nodes": "ros.nodes",
    "nodes.cdr": "ros.wire.cdr",
    "nodes.messages": "ros.wire.messages",
    "nodes.validation": "ros.wire.validation",
    "nodes.conversions": "ros.wire.conversions",
    "nodes.joint_messages": "ros.wire.joint_messages",
    "nodes.topics": "ros.wire.topics",
    "nodes.scene_messages": "ros.wire.scene_messages",
    "nodes.diagnostics": "ros.wire.diagnostics",
    "nodes.rate_loop": "ros.runtime.rate_loop",
    "nodes.looping_node": "ros.runtime.looping_node",
    "nodes.polling": "ros.runtime.polling",
    "nodes.runner": "ros.runtime.runner",
    "nodes.params": "ros.runtime.params",
    "nodes.throttled_log": "ros.runtime.throttled_log",
    "nodes.publisher_take": "ros.runtime.publisher_take",
    # viz: figures and pictures for a person
    "plotting": "viz.plotting",
    "figure_axes": "viz.figure_axes",
    "arm_animation": "viz.arm_animation",
    "collision_plot": "viz.collision_plot",
    "live_feed": "viz.live_feed",
    "markers": "viz.markers",
    "sweep": "viz.sweep",
    "plant.render": "viz.physics_render",
    # cli
    "teleop": "cli.teleop_keys",
}

#: Docstrings of the new packages (written where the package has no ``__init__.py`` yet).
PACKAGES: dict[str, str] = {
    "codegen": "Code generation, the only place that writes Python source: unrolled kinematics, linear algebra, the control step and the IK iteration, and their one cache.",
    "core": "The robot model and what follows from it directly: rotations, kinematics, loaders, bundled robots, URDF, scenes (no ROS).",
    "control": "Control laws and what shapes their commands: limits, integration, prediction, state machines, servoing, the QP law, offline simulation (no ROS).",
    "ik": "Inverse kinematics: iterative (damped least squares with restarts) and closed form (no ROS).",
    "motion": "Motions to follow: straight pose lines and joint-space trajectories, with their timing checks (no ROS).",
    "ros": "The ROS 2 side: the wire format (``wire``), the node runtime (``runtime``) and the node programs (``nodes``).",
    "ros.wire": "Messages on the wire: ROS messages <-> numpy, pre-serialised CDR, validation, topic names.",
    "ros.runtime": "What every manip_kin node runs on: the fixed-rate loop, polled subscriptions, parameters, logs, ``main()``.",
    "ros.nodes": "The node programs: thin adapters between ROS topics and one core object each.",
    "viz": "Pictures for a person: figures of a recorded run, animations, sweeps, markers and the live view's feed.",
}

#: Old test file (under ``test/``) -> new path (under ``test/``). Shared helpers go to ``support/``.
TESTS: dict[str, str] = {
    **{
        f"{name}.py": f"support/{name}.py"
        for name in (
            "bounded_cli",
            "collision_robots",
            "fake_hardware",
            "held_arm",
            "hostile_recordings",
            "hostile_robot_files",
            "kin_reference",
            "live_view_client",
            "node_harness",
            "opw_arm",
            "pipeline_checks",
            "record_collision_run",
            "net_namespaces",
            "across_hosts_run",
            "robot_data_files",
        )
    },
    **{
        f"test_{name}.py": f"core/test_{name}.py"
        for name in (
            "kinematics",
            "rotations",
            "loaders",
            "urdf",
            "urdf_chains",
            "tf_tree",
            "scene",
            "core_pieces",
            "hostile_robot_files",
            "mutation_survivors",
        )
    },
    "test_codegen.py": "codegen/test_codegen.py",
    "test_collision_broad_phase.py": "collision/test_collision_broad_phase.py",
    "test_motion_timing.py": "pipeline/test_motion_timing.py",
    "test_across_hosts.py": "pipeline/test_across_hosts.py",
    "test_prompt_acknowledgements.py": "pipeline/test_prompt_acknowledgements.py",
    **{
        f"test_{name}.py": f"control/test_{name}.py"
        for name in ("control", "command_filter", "reference_law", "simulation", "state_prediction", "qp_law")
    },
    "test_supervisors.py": "control/test_state_machines.py",
    **{f"test_{name}.py": f"ik/test_{name}.py" for name in ("ik", "ik_seeding", "closed_form")},
    "test_trajectory.py": "motion/test_lines.py",
    "test_joint_trajectory.py": "motion/test_joint_trajectory.py",
    "test_collision.py": "collision/test_collision.py",
    "test_physics_plant.py": "plant/test_physics_plant.py",
    **{
        f"test_{name}.py": f"recording/test_{name}.py"
        for name in (
            "recording_format",
            "recording_full_disk",
            "recording_intake",
            "recording_pipeline",
            "recording_recorder",
            "recording_replay",
            "recording_tf",
            "hostile_recordings",
            "physics_recording",
        )
    },
    "test_conversions.py": "ros/wire/test_conversions.py",
    "test_hostile_inputs.py": "ros/wire/test_hostile_inputs.py",
    **{
        f"test_{name}.py": f"ros/nodes/test_{name}.py"
        for name in (
            "nodes_collision",
            "nodes_controller",
            "nodes_generator",
            "nodes_hostile_messages",
            "nodes_joint_space",
            "nodes_loop_faults",
            "nodes_physics",
            "nodes_plumbing",
            "nodes_robot_state",
            "nodes_safety",
            "nodes_servo",
            "nodes_visuals",
            "live_tuning",
            "parameter_ranges",
            "collision_params",
            "robot_description",
            "live_view",
            "stop_signals",
            "ros2_control",
        )
    },
    **{
        f"test_{name}.py": f"pipeline/test_{name}.py"
        for name in (
            "pipeline",
            "pipeline_colcon",
            "pipeline_faults",
            "pipeline_joint_move",
            "pipeline_line",
            "pipeline_position_line",
            "two_arms",
        )
    },
    **{f"test_{name}.py": f"viz/test_{name}.py" for name in ("plotting", "collision_plot", "physics_render")},
    **{
        f"test_{name}.py": f"cli/test_{name}.py"
        for name in ("cli_closed_form", "cli_model", "cli_motion", "cli_teleop", "obstacle_cli")
    },
}

#: Names imported from a module that does not define them (a re-export) -> the module that does.
#: ``from manip_kin.M import a, b`` is split along this table, and ``ALIAS.a`` of a shim imported
#: as a module (``from manip_kin.ros.wire import conversions as conv``) becomes a direct import.
#: Modules listed in :data:`SHIMS` are deleted once nothing imports them.
REEXPORTS: dict[str, dict[str, str]] = {
    "ros.wire.conversions": {
        **dict.fromkeys(
            "DecodedPoseStamped Float64ArrayCdr JointStateCdr JointStateDecoder PoseStampedCdr TwistStampedCdr"
            " decode_float64_array decode_pose_stamped quaternion_of_pose_values".split(),
            "ros.wire.cdr",
        ),
        **dict.fromkeys(
            "DIAGNOSTIC_LEVELS diagnostic_values make_diagnostic_array make_diagnostic_status".split(),
            "ros.wire.diagnostics",
        ),
        **dict.fromkeys(
            "array_to_multiarray fill_joint_state fill_pose fill_pose_stamped fill_twist_stamped make_joint_state"
            " make_pose_stamped make_twist_stamped multiarray_to_array ns_to_stamp pose_stamped_to_matrix"
            " pose_to_matrix quaternion_to_matrix stamp_key stamp_key_to_ns stamp_to_ns stamp_to_seconds"
            " to_double_array twist_to_arrays".split(),
            "ros.wire.messages",
        ),
        **dict.fromkeys(
            "QUATERNION_TOLERANCE InvalidMessageError JointStateMapper check_command"
            " command_problem frame_problem pose_problem twist_problem".split(),
            "ros.wire.validation",
        ),
        "check_pose_stamped": "ros.wire.messages",
    },
    # a check that converts: beside the conversion (messages imports validation, not back)
    "ros.wire.validation": {"check_pose_stamped": "ros.wire.messages"},
    # rate_loop's lazy __getattr__ re-export of the node base class, and the names it imports
    "ros.runtime.rate_loop": {
        **dict.fromkeys(("LoopingNode", "LoopGaveUpError"), "ros.runtime.looping_node"),
        "PolledSubscription": "ros.runtime.polling",
        "ThrottledLog": "ros.runtime.throttled_log",
    },
    # the splits of the modules over 400 lines (issue 25): names that moved out of a module
    "ros.runtime.params": {
        **dict.fromkeys(("LiveParameters", "declare_parameters", "MAX_REASON"), "ros.runtime.declared_params"),
        "usage_text": "ros.runtime.usage",
    },
    "recording.msgdef": dict.fromkeys(
        "rihs01_from_schema rihs01_hash rosidl_type_hash type_description type_hash".split(), "recording.type_hash"
    ),
    "recording.writer": {
        **dict.fromkeys(("OutputLayout", "resolve_output"), "recording.output_layout"),
        **dict.fromkeys(("RecordingSummary", "format_bytes"), "recording.summary"),
    },
    "viz.plotting": dict.fromkeys(
        "PLOTTED_TOPIC_TYPES PoseSeries RunData TwistSeries load_run plotted_topics tracking_errors".split(),
        "viz.run_data",
    ),
    "motion.lines": dict.fromkeys(("ReachReport", "check_line_reachable"), "motion.line_reach"),
    "pipeline.supervisor": dict.fromkeys(
        "IRB120_LINE_GENERATOR PIPELINE_NODES NodeProcess find_executable pipeline_processes".split(),
        "pipeline.node_process",
    ),
    "pipeline.client": dict.fromkeys(("GOAL_RESEND_AFTER_S", "GOAL_RESENDS"), "pipeline.waiting"),
    **{
        f"ros.nodes.{node}": dict.fromkeys(
            ("NODE_NAME", "PARAMETERS", "STATES", "USAGE"), f"ros.nodes.{node}_interface"
        )
        for node in ("cartesian_controller", "trajectory_generator")
    },
    "ros.nodes.robot_state": dict.fromkeys(("NODE_NAME", "PARAMETERS", "USAGE"), "ros.nodes.robot_state_interface"),
}
SHIMS = ("ros.wire.conversions",)

TEXT_SUFFIXES = {".py", ".md", ".toml", ".cfg", ".txt", ".xml", ".yaml", ".yml", ".json", ".sh", ""}
SKIP_FILES = {"tools/relayout.py"}

_DOTTED = re.compile(r"(?<![\w.])manip_kin((?:\.[A-Za-z_]\w*)+)")
_PATH = re.compile(r"(?<![\w/.])manip_kin/((?:[A-Za-z_]\w*/)*[A-Za-z_]\w*)(\.py|/)?")
_TEST_PATH = re.compile(r"(?<![\w/.])test/([A-Za-z_]\w*\.py)")


def _git(root: Path, *args: str, check: bool = True) -> str:
    return subprocess.run(["git", *args], cwd=root, check=check, capture_output=True, text=True).stdout


def _module_path(root: Path, dotted: str) -> Path:
    return root / "manip_kin" / Path(*dotted.split("."))


def _exists(root: Path, dotted: str) -> bool:
    base = _module_path(root, dotted)
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def pending_clashes(root: Path) -> set[str]:
    """Old names that are also a new package (``control``, ``ik``) and still exist as old modules.

    ``manip_kin.control`` means the old module until it is moved and the new package after; only
    in the first case is a bare reference rewritten (what keeps a second run a no-op).
    """
    return {old for old in MODULES if old in _new_prefixes() and _module_path(root, old).with_suffix(".py").is_file()}


_PREFIXES: set[str] = set()


def _new_prefixes() -> set[str]:
    """Every new module and package name (``control``, ``control.qp``, ``control.qp.law``...)."""
    if not _PREFIXES:
        for new in MODULES.values():
            pieces = new.split(".")
            _PREFIXES.update(".".join(pieces[:k]) for k in range(1, len(pieces) + 1))
    return _PREFIXES


def map_module(parts: list[str], clashes: set[str]) -> list[str] | None:
    """The new dotted parts for old ``parts`` (the names after ``manip_kin``), or None to leave them.

    The longest table entry that prefixes ``parts`` decides; a prefix that is already a new name
    (longer than any old entry, or an old name that is now only a package) leaves it alone.
    """
    for k in range(len(parts), 0, -1):
        head = ".".join(parts[:k])
        if head in MODULES and (head not in _new_prefixes() or head in clashes):
            return MODULES[head].split(".") + parts[k:]
        if head in _new_prefixes():
            return None
    return None


_DONE = "\x00relayout-done\x00"
_FROM_IMPORT = re.compile(
    r"^(?P<indent>[ \t]*)from manip_kin(?P<package>(?:\.\w+)*) import (?P<names>[\w ,]+?)[ \t]*$", re.M
)


def _split_from_import(match: re.Match, clashes: set[str]) -> str:
    """``from manip_kin.P import a, b as c``: each name that is an old module imported from its new parent.

    A renamed module keeps its local name (``from manip_kin.ik import iteration as ik_iteration``);
    a name of :data:`REEXPORTS` is imported from the module that defines it.
    """
    package = [p for p in match.group("package").split(".") if p]
    indent = match.group("indent")
    kept, lines = [], {}
    for item in match.group("names").split(","):
        item = item.strip()
        if not item:
            continue
        name, _, alias = item.partition(" as ")
        name, alias = name.strip(), alias.strip()
        new = map_module([*package, name], clashes)
        owner = REEXPORTS.get(".".join(map_module(package, clashes) or package), {}).get(name)
        if new is not None:
            local = alias or name
            leaf = new[-1]
            entry = leaf if leaf == local else f"{leaf} as {local}"
            lines.setdefault(".".join(new[:-1]), []).append(entry)
        elif owner is not None:
            lines.setdefault(owner, []).append(item)
        else:
            kept.append(item)
    if not lines:
        return match.group(0)
    out = []
    if kept:
        base = map_module(package, clashes) or package
        out.append(f"{indent}from {'.'.join(['manip_kin', *base])} import {', '.join(kept)}")
    for parent, entries in lines.items():
        out.append(
            f"{indent}from {'.'.join(['manip_kin', *(parent.split('.') if parent else [])])} import {', '.join(entries)}"
        )
    return "\n".join(out)


_MULTI_IMPORT = re.compile(r"^(?P<indent>[ \t]*)from manip_kin\.(?P<module>[\w.]+) import \((?P<names>[^)]*)\)", re.M)


def _split_reexports(text: str) -> str:
    """``from <shim> import (a, b, ...)`` -> one import per module that defines the names."""

    def replace(match: re.Match) -> str:
        table = REEXPORTS.get(match.group("module"))
        if table is None:
            return match.group(0)
        names = [n.strip() for n in re.sub(r"#[^\n]*", "", match.group("names")).split(",") if n.strip()]
        by_module: dict[str, list[str]] = {}
        for item in names:
            by_module.setdefault(table.get(item.split(" as ")[0].strip(), match.group("module")), []).append(item)
        if list(by_module) == [match.group("module")]:
            return match.group(0)  # nothing re-exported: the statement stays as written
        indent = match.group("indent")
        return "\n".join(
            f"{indent}from manip_kin.{module} import {', '.join(found)}" for module, found in by_module.items()
        )

    return _MULTI_IMPORT.sub(replace, text)


def _bound_names(text: str, owners: dict[str, str]) -> set[str]:
    """Names ``text`` binds or reads as identifiers, except imports of the name from its owner."""
    import ast

    names = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.ImportFrom | ast.Import):
            for alias in node.names:
                local = alias.asname or alias.name
                if not (isinstance(node, ast.ImportFrom) and owners.get(local) == node.module and not alias.asname):
                    names.add(local)
    return names


def _inline_module_alias(text: str, path: str) -> str:
    """``from manip_kin.ros.wire import conversions as conv`` + ``conv.x`` -> ``from <owner> import x`` + ``x``."""
    for shim in SHIMS:
        parent, _, leaf = shim.rpartition(".")
        pattern = re.compile(
            rf"^(?P<indent>[ \t]*)from manip_kin\.{re.escape(parent)} import {leaf}(?: as (?P<alias>\w+))?[ \t]*\n",
            re.M,
        )
        match = pattern.search(text)
        if match is None:
            continue
        alias = match.group("alias") or leaf
        used = sorted(set(re.findall(rf"(?<![\w.]){alias}\.(\w+)", text)))
        table = REEXPORTS[shim]
        unknown = [name for name in used if name not in table]
        if unknown:
            raise SystemExit(f"relayout: {path}: {alias}.{unknown} are not in REEXPORTS[{shim!r}]")
        body = pattern.sub("", text, count=1)
        bound = _bound_names(body, {name: f"manip_kin.{table[name]}" for name in used})
        for name in used:
            if name in bound:
                raise SystemExit(f"relayout: {path}: {name} is already a name there; import {shim} by hand")
        body = re.sub(rf"(?<![\w.]){alias}\.(\w+)", r"\1", body)
        by_module: dict[str, list[str]] = {}
        for name in used:
            by_module.setdefault(table[name], []).append(name)
        imports = "".join(
            f"{match.group('indent')}from manip_kin.{module} import {', '.join(names)}\n"
            for module, names in sorted(by_module.items())
        )
        text = body[: match.start()] + imports + body[match.start() :]
    return text


def rewrite_text(text: str, clashes: set[str], path: str = "") -> str:
    """Every old module name, module path and test path in ``text``, rewritten to the new one."""

    def dotted(match: re.Match) -> str:
        parts = match.group(1)[1:].split(".")
        new = map_module(parts, clashes)
        return match.group(0) if new is None else "manip_kin." + ".".join(new)

    def module_path(match: re.Match) -> str:
        parts, suffix = match.group(1).split("/"), match.group(2) or ""
        new = map_module(parts, clashes)
        return match.group(0) if new is None else "manip_kin/" + "/".join(new) + suffix

    def test_path(match: re.Match) -> str:
        name = match.group(1)
        return f"test/{TESTS[name]}" if name in TESTS else match.group(0)

    if path.endswith(".py"):
        # Lines written here are final: hidden from the dotted pass (``from manip_kin.ik import
        # iteration`` must not read as the old module ``ik``).
        text = _FROM_IMPORT.sub(lambda m: _split_from_import(m, clashes).replace("manip_kin", _DONE), text)
    text = _DOTTED.sub(dotted, text).replace(_DONE, "manip_kin")
    if path.endswith(".py"):
        text = _split_reexports(text)
        text = _FROM_IMPORT.sub(lambda m: _split_from_import(m, clashes), text)
        text = _inline_module_alias(text, path)
    text = _PATH.sub(module_path, text)
    return _TEST_PATH.sub(test_path, text)


def _mv(root: Path, source: Path, target: Path, dry_run: bool) -> str:
    if target.exists():
        raise SystemExit(f"relayout: both {source} and {target} exist; merge them by hand")
    if not dry_run:
        target.parent.mkdir(parents=True, exist_ok=True)
        _git(root, "mv", str(source), str(target))
    return f"git mv {source.relative_to(root)} {target.relative_to(root)}"


def move_files(root: Path, dry_run: bool) -> list[str]:
    """``git mv`` of every table entry still at its old path; new packages get an ``__init__.py``."""
    done = []
    for dotted, doc in PACKAGES.items():
        init = _module_path(root, dotted) / "__init__.py"
        if not init.exists():
            done.append(f"create {init.relative_to(root)}")
            if not dry_run:
                init.parent.mkdir(parents=True, exist_ok=True)
                init.write_text(f'"""{doc}"""\n')
                _git(root, "add", str(init))
    for old, new in MODULES.items():
        source, target = _module_path(root, old), _module_path(root, new)
        if old == "nodes":
            continue  # its modules move one by one; the package goes when empty (below)
        if source.with_suffix(".py").is_file():
            source, target = source.with_suffix(".py"), target.with_suffix(".py")
        elif not (source / "__init__.py").is_file() or old in _new_prefixes():
            continue  # moved already (a package of the same name is the new one)
        done.append(_mv(root, source, target, dry_run))
    for old, new in TESTS.items():
        if (root / "test" / old).is_file():
            done.append(_mv(root, root / "test" / old, root / "test" / new, dry_run))
    old_nodes = root / "manip_kin" / "nodes"
    for source in sorted(old_nodes.glob("*.py")) if old_nodes.is_dir() else ():
        if source.stem != "__init__" and source.exists():  # the node programs: by the ``nodes`` entry
            target = _module_path(root, ".".join(map_module(["nodes", source.stem], set()))).with_suffix(".py")
            done.append(_mv(root, source, target, dry_run))
    if old_nodes.is_dir() and not dry_run:
        left = [p for p in old_nodes.iterdir() if p.name not in ("__init__.py", "__pycache__")]
        if left:
            raise SystemExit(f"relayout: manip_kin/nodes still holds {[p.name for p in left]}: add them to MODULES")
        done.append("git rm manip_kin/nodes/__init__.py")
        if not dry_run:
            if (old_nodes / "__init__.py").exists():
                _git(root, "rm", "-q", str(old_nodes / "__init__.py"))
            subprocess.run(["rm", "-rf", str(old_nodes)], check=True)
    return done


def rewrite_files(root: Path, clashes: set[str], dry_run: bool) -> list[str]:
    """Rewrite every tracked text file; then delete the shims nothing imports any more."""
    changed = []
    for name in _git(root, "ls-files").split("\n"):
        if not name or name in SKIP_FILES or Path(name).suffix not in TEXT_SUFFIXES:
            continue
        path = root / name
        if not path.is_file():
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        new = rewrite_text(text, clashes, name)
        if new != text:
            changed.append(f"rewrite {name}")
            if not dry_run:
                path.write_text(new)
    for shim in SHIMS:
        shim_file = _module_path(root, shim).with_suffix(".py")
        if shim_file.exists() and not dry_run:
            leftover = _git(
                root,
                "grep",
                "-l",
                "-E",
                rf"manip_kin\.{shim}\b|import {shim.rpartition('.')[2]}\b",
                "--",
                "*.py",
                check=False,
            )
            users = [u for u in leftover.split() if u != str(shim_file.relative_to(root)) and u not in SKIP_FILES]
            if users:
                raise SystemExit(f"relayout: {shim} is still imported by {users}")
        if shim_file.exists():
            changed.append(f"git rm {shim_file.relative_to(root)}")
            if not dry_run:
                _git(root, "rm", "-q", "-f", str(shim_file))
    return changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dry-run", action="store_true", help="print what would change, change nothing")
    args = parser.parse_args(argv)
    root = Path(_git(Path(__file__).resolve().parent, "rev-parse", "--show-toplevel").strip())
    clashes = pending_clashes(root)
    actions = move_files(root, args.dry_run)
    actions += rewrite_files(root, clashes, args.dry_run)
    print("\n".join(actions) if actions else "relayout: nothing to do (already in the new layout)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
