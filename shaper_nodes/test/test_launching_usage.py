"""The CPU of started processes (ros/launching.py ``UsagePopen``) and the suite's CPU report (scripts/test_cpu.py)."""

from __future__ import annotations

import importlib.util
import json
import pathlib
import subprocess
import sys
import time

from shaper_nodes.ros.launching import CPU_LOG_ENV, ChildProcess, UsagePopen, command_name

#: a child that spends about 0.3 s of CPU, then ends
BURN = "import time\nend = time.process_time() + 0.3\nwhile time.process_time() < end:\n    pass\n"
ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_wait_keeps_the_childs_cpu():
    proc = UsagePopen([sys.executable, "-c", BURN])
    assert proc.usage is None
    assert proc.wait(timeout=60) == 0
    assert proc.usage is not None
    assert proc.usage.ru_utime + proc.usage.ru_stime >= 0.25


def test_poll_keeps_the_childs_cpu_and_the_exit_code():
    proc = UsagePopen([sys.executable, "-c", BURN + "raise SystemExit(3)"])
    deadline = time.monotonic() + 60
    while proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.returncode == 3
    assert proc.usage is not None and proc.usage.ru_utime + proc.usage.ru_stime >= 0.25


def test_a_killed_child_is_reaped_with_its_usage():
    proc = UsagePopen([sys.executable, "-c", "import time; time.sleep(60)"])
    proc.kill()
    assert proc.wait(timeout=60) == -9
    assert proc.usage is not None


def test_child_process_cpu_after_stop(tmp_path):
    child = ChildProcess([sys.executable, "-c", BURN], log_path=tmp_path / "log")
    assert child.cpu is None
    child.start()
    assert child.proc is not None
    child.proc.wait(timeout=60)
    assert child.stop() == 0
    assert child.cpu is not None and child.cpu >= 0.25


def test_with_the_log_set_each_reaped_child_appends_a_line(tmp_path, monkeypatch):
    log = tmp_path / "cpu.jsonl"
    monkeypatch.setenv(CPU_LOG_ENV, str(log))
    for _ in range(2):
        UsagePopen([sys.executable, "-c", BURN]).wait(timeout=60)
    rows = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(rows) == 2
    for row in rows:
        assert row["kind"] == "process" and row["name"] == "python -c"
        assert row["user"] + row["sys"] >= 0.25
        assert row["test"].endswith("test_with_the_log_set_each_reaped_child_appends_a_line")


def test_without_the_log_nothing_is_written(tmp_path, monkeypatch):
    monkeypatch.delenv(CPU_LOG_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    UsagePopen([sys.executable, "-c", "pass"]).wait(timeout=60)
    assert list(tmp_path.iterdir()) == []


def test_subprocess_run_goes_through_a_popen_subclass_unchanged():
    out = subprocess.run([sys.executable, "-c", "print('x')"], capture_output=True, text=True, check=True)
    assert out.stdout == "x\n"  # the root conftest.py may have made subprocess.Popen a UsagePopen; run works the same


def test_command_names():
    assert command_name(["/opt/ws/lib/shaper_nodes/shaper_node", "--ros-args"]) == "shaper_node"
    demo = ["/venv/bin/python3", "-m", "sim_plant_node.clients.demo", "--x"]
    assert command_name(demo) == "python -m sim_plant_node.clients.demo"
    assert command_name(["python", "/a/b/arm_reference_bags.py"]) == "python arm_reference_bags.py"
    assert command_name(["python", "-c", "pass"]) == "python -c"
    assert command_name([]) == "?"


def _test_cpu():
    spec = importlib.util.spec_from_file_location("test_cpu_script", ROOT / "scripts" / "test_cpu.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_report_takes_a_parents_children_out_of_its_own_cpu(tmp_path):
    log = tmp_path / "cpu.jsonl"
    rows = [
        {"kind": "process", "name": "demo", "pid": 10, "parent": 1, "user": 5.0, "sys": 1.0, "wall": 9, "test": "t::a"},
        {"kind": "process", "name": "sim_plant", "pid": 11, "parent": 10, "user": 3.0, "sys": 0.5, "wall": 8,
         "test": "t::a"},
        {"kind": "test", "test": "t::a", "pid": 1, "wall": 10.0, "user": 1.0, "sys": 0.0, "children_user": 5.0,
         "children_sys": 1.0},
        {"kind": "test", "test": "t::b", "pid": 1, "wall": 1.0, "user": 0.5, "sys": 0.0, "children_user": 0.0,
         "children_sys": 0.0},
    ]
    log.write_text("".join(json.dumps(r) + "\n" for r in rows))
    script = _test_cpu()
    _, procs = script.read(str(log))
    own = {p["name"]: cpu for p, cpu in script.own_cpu(procs)}
    assert own == {"demo": 2.5, "sim_plant": 3.5}
    text = script.summary(str(log))
    assert "2 tests: 8 s of CPU (2 s in pytest, 6 s in 2 processes they started)" in text
    assert text.index("t::a") < text.index("t::b")
    assert "| demo | 1 | 2.5 |" in text and "| sim_plant | 1 | 3.5 |" in text
    assert "2 tests in both: 8 s of CPU before, 8 s after (1.00)" in script.compare(str(log), str(log))
