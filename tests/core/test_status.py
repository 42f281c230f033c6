"""What an online identifier publishes from (genbacklash_core.online.status)."""

from __future__ import annotations

from genbacklash_core import RecursiveIdentifier, WindowedIdentifier, paper_example


def test_the_identifier_and_its_parts_share_one_status_made_anew_at_each_reset() -> None:
    data = paper_example(1).generate(seed=0, n_samples=1200)
    for ident in (WindowedIdentifier(3), RecursiveIdentifier(3)):
        ident.update_many(data.u, data.y)
        status = ident._status
        assert status.samples == 1200 and status.sign_now
        assert status.structure is ident.structure
        ident.reset()
        assert ident._status is not status
        assert (ident._status.samples, ident._status.reason) == (0, "warming up")
        assert ident.estimate.samples == 0
