"""Tests of model/io/summary.py: counts and keys from the meta device, JSON CLI."""

import json

from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.io.summary import main
from infinihand_ros.model.io.summary import summarize


def test_paper_summary_counts_match_lingbot_map_plus_mask_head() -> None:
    """The paper summary lists per-module counts whose upstream part is LingBot-Map's."""
    summary = summarize(named_config_path('paper'))
    params = summary['params']
    assert params['aggregator'] + params['camera_head'] + params['depth_head'] == 1_157_943_540
    assert params['total'] == sum(count for name, count in params.items() if name != 'total')
    assert summary['keys']['aggregator.patch_embed.pos_embed'] == [1, 1370, 1024]


def test_json_cli_prints_params_and_keys(capsys) -> None:
    """--json prints {"params": ..., "keys": ...} for the tiny configuration."""
    assert main(['--config', str(named_config_path('tiny')), '--json']) == 0
    printed = json.loads(capsys.readouterr().out)
    assert set(printed) == {'params', 'keys'}
    assert printed['keys']['aggregator.patch_embed.proj.weight'] == [192, 3, 14, 14]
    assert printed['params']['total'] > 0


def test_cli_rejects_a_bad_config(tmp_path, capsys) -> None:
    """An unknown key makes the CLI exit 1 with the key named."""
    bad = tmp_path / 'bad.yaml'
    bad.write_text('geometry:\n  aggregator:\n    width: 3\n')
    assert main(['--config', str(bad)]) == 1
    assert 'width' in capsys.readouterr().err
