"""Work per request is capped (issue 16), and `beyond ask` waits for the reasoner it needs.

An AffordanceQuery over 18 word variables made 262,144 rows and blocked the reasoner's event loop
for 4.7 s; `beyond ask` failed 7 times out of 12 against a running reasoner, because it queried
before discovery had found the reasoner's queryable.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from busutil_net import REPO, env_for, private_config

from beyond_self.cli import main
from beyond_self.cognition.bn import BayesNet, learn_network, synthetic_dataset
from beyond_self.cognition.bn.inference import MAX_JOINT_ROWS, MAX_QUERY_WORK
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.session import Bus
from beyond_self.services.launcher import BEYOND

ASKS = 50


@pytest.fixture(scope="module")
def network() -> BayesNet:
    return learn_network(synthetic_dataset())


def _words(model: BayesNet, n: int) -> list[str]:
    core = set(model.compiled.core_names)
    return [v for v in model.variables if v not in core][:n]


def test_the_joint_of_every_affordance_node_is_answered(network: BayesNet) -> None:
    core = list(network.compiled.core_names)
    posterior = network.query(core)
    assert posterior.table.size <= MAX_JOINT_ROWS
    assert posterior.table.sum() == pytest.approx(1.0)


def test_a_query_over_too_many_rows_is_refused_with_the_limit(network: BayesNet) -> None:
    with pytest.raises(InputError, match=f"over the limit of {MAX_JOINT_ROWS}"):
        network.query(_words(network, 18))  # 262,144 rows


def test_a_query_over_too_much_work_is_refused_with_the_limit(network: BayesNet) -> None:
    words = _words(network, 10)  # 1,024 rows, each summed over 2,592 affordance states
    with pytest.raises(InputError, match=f"over the limit of {MAX_QUERY_WORK}"):
        network.query(words)
    # the same words with evidence leave fewer states to sum over: answered
    posterior = network.query(words, {"Action": "grasp", "Shape": "box", "Size": "big"})
    assert posterior.table.shape == (2,) * 10
    assert float(posterior.table.sum()) == pytest.approx(1.0)


def test_bn_query_shares_the_cap(
    network: BayesNet, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from beyond_self.cognition.bn import save_model

    path = tmp_path / "model.json"
    save_model(network, path)
    assert main(["bn", "query", str(path), "--query", *_words(network, 18)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"limit of {MAX_JOINT_ROWS}" in err[0]


def test_ask_succeeds_every_time_against_a_running_reasoner(
    network: BayesNet, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    config = private_config()
    reasoner = subprocess.Popen(
        [*BEYOND, "service", "reasoner"],
        cwd=REPO,
        env=env_for(config),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:

        async def alive() -> None:
            with Bus.open(config) as bus:
                await bus.wait_alive(bus.keys.alive("reasoner"), timeout=120)

        asyncio.run(alive())
        monkeypatch.setenv("BEYOND_ROBOT", config.robot)
        monkeypatch.setenv("BEYOND_ZENOH_PORT", str(config.port))
        argv = ["ask", "--query", "Action", "--evidence", "Shape=box", "--json", "--timeout", "30"]
        expected = network.query(["Action"], {"Shape": "box"}).marginal("Action")
        codes = []
        for _ in range(ASKS):  # each ask opens a new session: discovery starts from nothing
            capsys.readouterr()
            codes.append(main(argv))
            if codes[-1] == 0:
                answer = json.loads(capsys.readouterr().out)
                got = {row["assignment"]["Action"]: row["p"] for row in answer["rows"]}
                assert got.keys() == expected.keys()
                np.testing.assert_allclose([got[k] for k in expected], list(expected.values()))
        assert codes == [0] * ASKS, capsys.readouterr().err
        capsys.readouterr()
        too_big = ["ask", "--query", *_words(network, 18), "--timeout", "30"]
        assert main(too_big) == 2  # refused by the reasoner, with the limit, on one line
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"limit of {MAX_JOINT_ROWS}" in err[0], err
        assert main(argv) == 0  # and the reasoner still answers
    finally:
        reasoner.terminate()
        reasoner.wait(30)


def test_description_caps_are_in_the_library() -> None:
    """`describe --nbest 1000000000000` reached 5 GB before a MemoryError: refused up front."""
    from beyond_self.cognition.descriptions import NBEST_MAX, SAMPLES_MAX, nbest_exact, sample_keys

    with pytest.raises(InputError, match=f"up to {NBEST_MAX}"):
        nbest_exact({}, 10**12)
    with pytest.raises(InputError, match=f"0..{SAMPLES_MAX}"):
        sample_keys(SAMPLES_MAX + 1, 0)
    assert len(sample_keys(5, 0)) == 5
