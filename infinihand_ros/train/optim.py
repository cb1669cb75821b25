"""Parameter groups, freezing, AdamW and the warm-up + cosine schedule (paper Sec. 4.1).

``assign_parameters`` sorts a model's named parameters into the configured groups: a name under
a ``frozen`` prefix stops training (``requires_grad = False``); any other goes to the first
group one of whose prefixes starts it; a trainable name in no group is an error, so a config
never trains (or freezes) something by accident. The schedule multiplies every group's rate by
``(step + 1) / warmup`` during the warm-up, then by a cosine from 1 to ``min_lr_ratio`` at the
last step.
"""

import math

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.train_config import OptimConfig
import torch
from torch import nn

#: Examples listed when parameters match no group.
_LIST_LIMIT = 5


def assign_parameters(model: nn.Module, config: OptimConfig
                      ) -> dict[str, list[tuple[str, nn.Parameter]]]:
    """Freeze the ``frozen`` parameters and return the others by group name (config order).

    Raises:
        ConfigError: when a trainable parameter matches no group, or a group matches nothing.

    """
    groups: dict[str, list[tuple[str, nn.Parameter]]] = {group.name: []
                                                         for group in config.groups}
    unmatched = []
    for name, parameter in model.named_parameters():
        if name.startswith(tuple(config.frozen)):
            parameter.requires_grad_(False)
            continue
        group = next((group for group in config.groups
                      if any(name.startswith(prefix) for prefix in group.prefixes)), None)
        if group is None:
            unmatched.append(name)
        else:
            groups[group.name].append((name, parameter))
    if unmatched:
        raise ConfigError(f'train.optim: {len(unmatched)} parameter(s) in no group and not '
                          f'frozen, e.g. {unmatched[:_LIST_LIMIT]}; add a prefix to a group '
                          'or to frozen')
    empty = [name for name, members in groups.items() if not members]
    if empty:
        raise ConfigError(f'train.optim.groups: {empty} match no trainable parameter; fix '
                          'their prefixes or remove them')
    return groups


def build_optimizer(model: nn.Module, config: OptimConfig) -> torch.optim.AdamW:
    """Return AdamW over the trainable groups (rates and weight decay from ``config``).

    Raises:
        ConfigError: see ``assign_parameters``.

    """
    rates = {group.name: group.lr for group in config.groups}
    groups = [{'params': [parameter for _, parameter in members], 'lr': rates[name],
               'name': name}
              for name, members in assign_parameters(model, config).items()]
    return torch.optim.AdamW(groups, betas=config.betas, eps=config.eps,
                             weight_decay=config.weight_decay)


def schedule_factor(step: int, total_steps: int, warmup_steps: int,
                    min_lr_ratio: float) -> float:
    """Return the rate multiplier of optimizer step ``step`` (0-based) of ``total_steps``."""
    if step < warmup_steps:
        return (step + 1) / warmup_steps
    span = max(1, total_steps - 1 - warmup_steps)
    progress = min(1.0, (step - warmup_steps) / span)
    return min_lr_ratio + (1.0 - min_lr_ratio) * 0.5 * (1.0 + math.cos(math.pi * progress))


def build_scheduler(optimizer: torch.optim.Optimizer, config: OptimConfig,
                    total_steps: int) -> torch.optim.lr_scheduler.LambdaLR:
    """Return the linear warm-up + cosine schedule over ``total_steps`` optimizer steps."""
    def factor(step: int) -> float:
        return schedule_factor(step, total_steps, config.warmup_steps, config.min_lr_ratio)

    return torch.optim.lr_scheduler.LambdaLR(optimizer, factor)
