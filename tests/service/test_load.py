"""A small load on a real ``starnav serve`` process: concurrent clients, every job answered,
each answer the solution of its own input (benchmarks/service/service_load.py is the large one)."""

from __future__ import annotations

import pytest

from service_helpers import load_jobs, run_load
from shared_data import LYRA

pytestmark = [pytest.mark.service, pytest.mark.slow]

TOLERANCE_ARCSEC = 60.0


def test_concurrent_clients_each_get_their_own_answer(nova_server):
    jobs = load_jobs(20, [LYRA], kinds=("list",), seed=18)
    outcomes = run_load(nova_server.url, jobs, clients=5)
    lost = [o for o in outcomes if o.status is None]
    assert not lost, lost[:3]
    assert len({o.job_id for o in outcomes}) == len(jobs)
    for o in outcomes:
        assert o.status == "success", o
        assert o.stars_from_input, f"job {o.job_id} answered with stars of another list"
        assert o.offset_arcsec < TOLERANCE_ARCSEC, o
