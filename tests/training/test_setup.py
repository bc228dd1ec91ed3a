"""The run's set-up: which body the agent's frames are drawn on."""

import json

from virl_quad.training.setup import drawn_as


def test_the_agent_is_drawn_on_the_body_the_fit_found_in_the_video(tmp_path):
    assert drawn_as(tmp_path, "pupper") is None                       # no fit: its own body
    (tmp_path / "prior_fit.json").write_text(json.dumps({"body": "pupper"}))
    assert drawn_as(tmp_path, "pupper") is None                       # the video shows a Pupper
    (tmp_path / "prior_fit.json").write_text(json.dumps({"body": "laikago"}))
    assert drawn_as(tmp_path, "pupper") == "laikago"
