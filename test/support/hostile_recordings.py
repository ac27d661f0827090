"""Hostile recordings: ``manip_kin info``, ``info --salvage`` and ``plot`` in a process bounded by setrlimit.

Run as a script (``python hostile_recordings.py OUT.json N``) by ``test_hostile_recordings.py``.
The files are real: written by :class:`~manip_kin.recording.RecordingWriter` (the recorder's
writer), then damaged: the cases of issue 29 one by one (:func:`cases`) and hypothesis
mutations (bit flips, hostile lengths, truncations, inserted and repeated bytes, broken
metadata). For every one, each command exits 0, or 2 with one line on stderr; never a
traceback, within a CPU alarm per command and the process's RLIMIT_AS.
"""

from __future__ import annotations

import io
import json
import os
import struct
import sys
import tempfile
import zlib
from pathlib import Path

import zstandard
from bounded_cli import first_failure, limit_this_process, one_line_refusal_problem, run_cli, save_progress

SECRET = b"SECRET-BYTES-OUTSIDE-THE-BAG"
HOSTILE_U64 = [2**64 - 1, 2**40, 2**63, 0, 1, 0xFFFFFFFF]
MAGIC = b"\x89MCAP0\r\n"


def _record(opcode: int, body: bytes) -> bytes:
    return bytes([opcode]) + struct.pack("<Q", len(body)) + body


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def chunk_offsets(data: bytes) -> list[int]:
    """Offsets of the top-level chunk records of a valid file (walking record by record)."""
    offsets, offset = [], len(MAGIC)
    while offset + 9 <= len(data):
        opcode = data[offset]
        (length,) = struct.unpack_from("<Q", data, offset + 1)
        if opcode == 0x06:
            offsets.append(offset)
        if opcode == 0x02:
            break
        offset += 9 + length
    return offsets


def bomb_file(declared: int, real: int) -> bytes:
    """A small MCAP file whose one chunk declares ``declared`` bytes and inflates to ``real`` zeros."""
    compressor = zstandard.ZstdCompressor(level=19)
    sink = io.BytesIO()
    crc = 0
    with compressor.stream_writer(sink, closefd=False) as writer:
        block = b"\x00" * (1 << 20)
        for _ in range(real >> 20):
            writer.write(block)
            crc = zlib.crc32(block, crc)
    data = sink.getvalue()
    header = _record(0x01, _string("ros2") + _string("bomb"))
    chunk = _record(
        0x06, struct.pack("<QQQI", 0, 1, declared, crc) + _string("zstd") + struct.pack("<Q", len(data)) + data
    )
    footer = _record(0x02, struct.pack("<QQI", 0, 0, 0))
    return MAGIC + header + chunk + _record(0x0F, struct.pack("<I", 0)) + footer + MAGIC


def _metadata_bag(root: Path, name: str, source: Path, metadata: str) -> Path:
    bag = root / name
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(source.read_bytes())
    (bag / "metadata.yaml").write_text(metadata)
    return bag


def _recording_with_schema(path: Path, topic: str, type_name: str, text: str, data: bytes) -> Path:
    from manip_kin.recording import RecordingWriter

    with RecordingWriter(path) as writer:
        writer.add_topic(topic, type_name, schema=("ros2msg", text), type_description_hash="")
        for i in range(5):
            writer.write_raw(topic, data, 1_700_000_000_000_000_000 + i * 10**7)
    return path


def cases(root: Path, run: Path) -> dict[str, Path]:
    """The issue's cases, one recording (file or bag directory) each."""
    source = run.read_bytes()
    first, middle = chunk_offsets(source)[0], chunk_offsets(source)[len(chunk_offsets(source)) // 2]
    made: dict[str, Path] = {}

    def damaged(name: str, offset: int, value: bytes) -> None:
        data = bytearray(source)
        data[offset : offset + len(value)] = value
        made[name] = root / f"{name}.mcap"
        made[name].write_bytes(bytes(data))

    damaged("chunk_length_2_64", first + 1, struct.pack("<Q", 2**64 - 1))
    damaged("chunk_length_2_40", first + 1, struct.pack("<Q", 2**40))
    damaged("chunk_size_2_64", first + 9 + 16, struct.pack("<Q", 2**64 - 1))
    damaged("chunk_size_2_40", first + 9 + 16, struct.pack("<Q", 2**40))
    damaged("middle_chunk_bits", middle + 60, bytes(b ^ 0xFF for b in source[middle + 60 : middle + 68]))
    for name, declared, real in (("bomb_declared", 1 << 30, 1 << 30), ("bomb_understated", 1 << 20, 1 << 30)):
        made[name] = root / f"{name}.mcap"
        made[name].write_bytes(bomb_file(declared, real))
    metadata = {
        "metadata_damaged": "rosbag2_bagfile_information: [unclosed\n",
        "metadata_list": "- rosbag2_bagfile_information\n- 5\n",
        "metadata_paths_5": "rosbag2_bagfile_information:\n  relative_file_paths: 5\n",
        "metadata_paths_escape": "rosbag2_bagfile_information:\n  relative_file_paths: [../../outside.mcap]\n",
        "metadata_alias_bomb": "a: &a [x, x, x, x, x, x, x, x, x]\n"
        + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}' if i > 1 else '*a'] * 9)}]\n" for i in range(1, 9))
        + "rosbag2_bagfile_information: {relative_file_paths: [bag_0.mcap]}\n",
    }
    for name, text in metadata.items():
        made[name] = _metadata_bag(root, name, run, text)
    outside = root / "outside.bin"
    outside.write_bytes(SECRET * 4)
    bag = root / "symlinked_mcap"
    bag.mkdir()
    os.symlink(outside, bag / "bag_0.mcap")
    made["symlinked_mcap"] = bag
    made["schema_this"] = _recording_with_schema(
        root / "this.mcap",
        "/joint_velocity_commands",
        "this/msg/Thing",
        "float64[] data\n",
        b"\x00\x01\x00\x00" + b"\x00" * 4,
    )
    made["wrong_schema"] = _recording_with_schema(
        root / "wrong.mcap",
        "/tool_pose",
        "std_msgs/msg/String",
        "string data\n",
        b"\x00\x01\x00\x00\x02\x00\x00\x00x\x00",
    )
    made["wrong_type_data"] = _recording_with_schema(
        root / "wrong_data.mcap",
        "/joint_states",
        "sensor_msgs/msg/JointState",
        "string data\n",
        b"\x00\x01\x00\x00\x02\x00\x00\x00x\x00",
    )
    return made


def commands(path: Path, out_dir: Path) -> dict[str, list[str]]:
    return {
        "info": ["info", str(path)],
        "info_json": ["info", str(path), "--json"],
        "salvage": ["info", "--salvage", str(out_dir / f"{path.name}_salvaged.mcap"), str(path)],
        "plot": ["plot", str(path), "--out", str(out_dir / f"{path.name}_plots")],
    }


def run_all(path: Path, out_dir: Path) -> dict[str, dict]:
    results = {}
    for name, args in commands(path, out_dir).items():
        result = run_cli(args)
        result["problem"] = _problem(name, result, path)
        results[name] = result
    return results


def _problem(command: str, result: dict, path: Path) -> str | None:
    if SECRET[:6].decode() in result["stdout"] + result["stderr"]:  # even the first bytes
        return "bytes of a file outside the bag were printed"
    if "Zen of Python" in result["stdout"] + result["stderr"] or "this" in sys.modules:
        return "a module named by the recording was imported"
    if result["rc"] == 0:
        if command == "info_json":
            try:
                json.loads(result["stdout"], parse_constant=lambda name: (_ for _ in ()).throw(ValueError(name)))
            except ValueError as error:
                return f"info --json printed invalid JSON: {error}"
        if command == "salvage":
            output = Path(result["args"][2])
            check = run_cli(["info", str(output)])
            if check["rc"] != 0:
                return f"the salvaged file does not read back: {check.get('escaped') or check['stderr']}"
        return None
    return one_line_refusal_problem(result, str(path))


METADATA = "metadata.yaml"


def run_hypothesis(root: Path, bases: dict[str, Path], examples: int) -> str | None:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    import manip_kin.cli.plot_commands as plot_commands

    # Figures are drawn by the named cases; here plot reads the run and computes the errors only.
    from manip_kin.viz.run_data import tracking_errors

    plot_commands.plot_run = lambda run, out_dir, title="": [tracking_errors(run)] and []
    bag = bases.pop("bag")  # a bag directory the writer made: its metadata.yaml is mutated
    mcap_name, bag_mcap = next((f.name, f.read_bytes()) for f in bag.glob("*.mcap"))
    contents = {name: path.read_bytes() for name, path in bases.items()}
    contents[METADATA] = (bag / METADATA).read_bytes()
    counter = iter(range(10**9))

    @st.composite
    def mutated(draw):
        name = draw(st.sampled_from(sorted(contents)))
        data = bytearray(contents[name])
        for _ in range(draw(st.integers(1, 3))):
            kind = draw(st.sampled_from(["flip", "flip", "u64", "u64", "truncate", "insert", "repeat"]))
            at = draw(st.integers(0, max(0, len(data) - 1)))
            if kind == "flip":
                data[at] ^= 1 << draw(st.integers(0, 7))
            elif kind == "u64" and at + 8 <= len(data):
                data[at : at + 8] = struct.pack("<Q", draw(st.sampled_from(HOSTILE_U64)))
            elif kind == "truncate":
                del data[at:]
            elif kind == "insert":
                data[at:at] = draw(st.binary(min_size=1, max_size=16))
            elif kind == "repeat":
                data[at:at] = data[at : at + draw(st.integers(1, 200))]
        return name, bytes(data)

    @settings(
        derandomize=True, max_examples=examples, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(mutated())
    def check(named):
        name, data = named
        path = root / f"mutated_{next(counter):04d}_{name}"
        if name == METADATA:  # a bag directory: the writer's file, its metadata.yaml mutated
            path.mkdir()
            (path / mcap_name).write_bytes(bag_mcap)
            (path / METADATA).write_bytes(data)
        else:
            path.write_bytes(data)
        for command, result in run_all(path, root).items():
            assert result["problem"] is None, f"{command} of {name} mutated: {result['problem']}"

    return first_failure(check)


def main(out: str, examples: int) -> None:
    limit_this_process()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "recording"))  # a subprocess: no conftest
    from test_recording_format import write_recording

    from manip_kin.recording import read_info

    results: dict = {}
    with tempfile.TemporaryDirectory() as directory:
        root = Path(directory)
        run = root / "run.mcap"
        write_recording(run, chunk_size=1024)
        plain = root / "plain.mcap"
        write_recording(plain, compression="none", chunk_size=1024)
        lz4 = root / "lz4.mcap"
        write_recording(lz4, compression="lz4", chunk_size=1024)
        write_recording(root / "bag", chunk_size=1024)
        results["chunk_count"] = len(chunk_offsets(run.read_bytes()))
        for name, path in cases(root, run).items():
            results[name] = run_all(path, root)
            salvaged = Path(results[name]["salvage"]["args"][2])
            if results[name]["salvage"]["rc"] == 0:
                results[name]["salvaged_count"] = read_info(salvaged).message_count
            save_progress(out, results)
        results["hypothesis"] = {
            "problem": run_hypothesis(
                root, {"run.mcap": run, "plain.mcap": plain, "lz4.mcap": lz4, "bag": root / "bag"}, examples
            )
        }
    save_progress(out, results)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
