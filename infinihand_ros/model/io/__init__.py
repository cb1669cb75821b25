# noqa: A005 -- named io on purpose: the model's I/O, imported as infinihand_ros.model.io
"""Checkpoints, converters and command-line tools of the model (no network code here).

Modules: ``checkpoint`` (the one checkpoint format, checked state-dict loading), ``compose``
(one model from a whole-model, a geometry and a crop-encoder checkpoint), ``torch_checkpoint``
(reading upstream pickles safely), ``convert_lingbot_map`` (LingBot-Map / VGGT weights ->
geometry checkpoint), ``convert_wilor`` (WiLoR weights -> crop-encoder checkpoint) and
``summary`` (parameter counts and keys of a config, on the meta device).
"""
