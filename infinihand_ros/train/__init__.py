"""Training of InfiniHand (paper Sec. 3.2-3.3, Sec. 4.1 and appendix B).

Subpackage ``losses``: every loss term of appendix B as a pure function of plain tensors, with
its weights in ``config/train_losses.yaml``. Modules: ``train_config`` (``TrainConfig``,
``config/train_*.yaml``), ``config_compose`` (base files and dotted ``--set`` overrides),
``sequence_reader`` (format-driven sequence readers, per-sequence targets), ``clip_data``
(clips, resumable sampler, loader), ``clip_runner`` (the model over a clip's windows, box
sampling), ``loss_adapter`` (model outputs to loss arguments), ``optim`` (parameter groups,
AdamW, warm-up + cosine), ``train_state`` (checkpoints, resume), ``loss_log`` (JSON lines /
CSV log, PNG curves), ``distributed`` (torchrun + DDP), ``trainer`` (the loop shared by both
stages), ``cli`` (the ``train`` console script), and ``recipe`` / ``recipe_runner`` (a bundled
model's lineage: data, stages, export, evaluation).
"""
