"""Command-line overrides of the estimator: `--estimator paper` is the paper's law."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from agents.loading.scenario_file import load_scenario
from agents.shell.network_args import (
    NetworkOptions,
    add_network_arguments,
    apply_network_arguments,
    network_overrides,
)
from errors import ScenarioError


def parse(*argv: str) -> NetworkOptions:
    parser = argparse.ArgumentParser()
    add_network_arguments(parser)
    return NetworkOptions.from_namespace(parser.parse_args(list(argv)))


def test_the_estimator_order_follows_the_scenario_unless_overridden() -> None:
    ring = load_scenario("ring16")
    assert apply_network_arguments(ring, parse()).gains.estimator_order == 2
    assert apply_network_arguments(ring, parse("--estimator-order", "1")).gains.estimator_order == 1
    paper = apply_network_arguments(ring, parse("--estimator", "paper"))
    assert (paper.network.estimator, paper.gains.estimator_order) == ("paper", 1)
    assert apply_network_arguments(load_scenario(), parse("--estimator-order", "2")) \
        .gains.estimator_order == 2
    with pytest.raises(ScenarioError, match="--estimator-order"):
        apply_network_arguments(ring, parse("--estimator", "paper", "--estimator-order", "2"))


def test_the_order_reaches_the_children() -> None:
    assert network_overrides(parse("--estimator-order", "1")) == ["--estimator-order", "1"]
    with pytest.raises(SystemExit):
        parse("--estimator-order", "3")


def test_every_flag_reaches_the_children_as_given() -> None:
    argv = ["--estimator", "paper", "--link", "udp", "--delay-ms", "5.0", "--loss-model",
            "gilbert_elliott", "--impair-seed", "7", "--latency-stamps"]
    opts = parse(*argv)
    assert network_overrides(opts) == argv
    assert parse(*network_overrides(opts)) == opts  # a child reads back what it was given
    assert network_overrides(parse()) == []


def test_the_zenoh_runtime_follows_the_scenario_unless_overridden() -> None:
    ring32, paper = load_scenario("ring32"), load_scenario()
    assert (ring32.network.zenoh_runtime, paper.network.zenoh_runtime) == ("one_thread", "split")
    assert apply_network_arguments(ring32, parse()).network.zenoh_runtime == "one_thread"
    split = apply_network_arguments(ring32, parse("--zenoh-runtime", "split"))
    assert split.network.zenoh_runtime == "split"
    assert network_overrides(parse("--zenoh-runtime", "one_thread")) == \
        ["--zenoh-runtime", "one_thread"]
    with pytest.raises(SystemExit):
        parse("--zenoh-runtime", "two_threads")


def test_agent_sched_follows_the_scenario_unless_overridden() -> None:
    ring64, paper = load_scenario("ring64"), load_scenario()
    assert (ring64.network.agent_sched, paper.network.agent_sched) == ("batch", "normal")
    normal = apply_network_arguments(ring64, parse("--agent-sched", "normal"))
    assert normal.network.agent_sched == "normal"
    assert network_overrides(parse("--agent-sched", "batch")) == ["--agent-sched", "batch"]
    with pytest.raises(SystemExit):
        parse("--agent-sched", "fifo")


@pytest.mark.realtime
def test_batch_is_set_on_the_calling_thread_and_inherited_by_its_threads() -> None:
    import os
    import threading

    from agents.shell.process import apply_agent_sched

    seen: dict[str, int] = {}
    before = os.sched_getscheduler(0)  # as the test runner set it

    def agent() -> None:  # a thread of its own: pytest's main thread keeps its policy
        apply_agent_sched(load_scenario("ring64").network)
        seen["self"] = os.sched_getscheduler(0)
        child = threading.Thread(target=lambda: seen.update(child=os.sched_getscheduler(0)))
        child.start()
        child.join()

    t = threading.Thread(target=agent)
    t.start()
    t.join(timeout=10)
    assert seen == {"self": os.SCHED_BATCH, "child": os.SCHED_BATCH}
    assert os.sched_getscheduler(0) == before
    apply_agent_sched(load_scenario().network)  # "normal": nothing changes
    assert os.sched_getscheduler(0) == before


@pytest.mark.realtime
def test_yield_cpu_lowers_the_thread_and_its_own_sessions_autogroup(tmp_path: Path) -> None:
    import os
    import threading

    from agents.shell.process import yield_cpu

    group = tmp_path / "autogroup"
    seen: dict[str, object] = {}

    def agent(own_session: bool, key: str) -> None:  # nice is per thread on Linux
        before = os.getpriority(os.PRIO_PROCESS, 0)
        seen[key] = (yield_cpu(3, group, own_session=own_session),
                     os.getpriority(os.PRIO_PROCESS, 0) - before)

    for own, key in ((False, "shared"), (True, "own")):
        t = threading.Thread(target=agent, args=(own, key))
        t.start()
        t.join(timeout=10)
    assert seen["shared"] == ("thread", 3)  # never the autogroup of a session not ours
    assert seen["own"] == ("autogroup", 3) and group.read_text() == "3\n"
    t = threading.Thread(target=agent, args=(True, "none"))
    group.unlink()
    group.mkdir()  # unwritable as a file: a kernel without autogroups
    t.start()
    t.join(timeout=10)
    assert seen["none"] == ("thread", 3)


def test_agent_nice_is_the_scenarios_whole_number_and_off_by_default() -> None:
    from agents.loading.scenario_file import parse_scenario, shipped_text

    base = shipped_text("paper")
    assert load_scenario().network.agent_nice == 0
    assert load_scenario("ring64").network.agent_nice == 0  # tried at 5: ring64.toml
    assert parse_scenario(base + "\n[network]\nagent_nice = 19\n").network.agent_nice == 19
    for bad in ("-1", "20", "2.5", "true", '"5"'):
        with pytest.raises(ScenarioError, match=r"network\.agent_nice"):
            parse_scenario(base + f"\n[network]\nagent_nice = {bad}\n")
