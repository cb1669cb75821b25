"""The adapter mapping: dataset name -> function yielding its ``CorpusSequence`` objects.

Every entry takes the dataset roots and the ``AdapterContext``; ``build_corpus`` has one
command-line flag per name (``--dexycb DIR ...``).
"""

from collections.abc import Callable
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.corpus.adapters.arctic import iter_arctic
from infinihand_ros.corpus.adapters.dexycb import iter_dexycb
from infinihand_ros.corpus.adapters.egodex import iter_egodex
from infinihand_ros.corpus.adapters.ho3d import iter_ho3d
from infinihand_ros.corpus.adapters.hot3d import iter_hot3d
from infinihand_ros.corpus.adapters.lerobot_bags import iter_lerobot
from infinihand_ros.corpus.adapters.synthetic import iter_synthetic
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.mano.mano_file import ManoData


@dataclass(frozen=True)
class AdapterContext:
    """What some adapters need besides their roots.

    Attributes:
        mano: real MANO arrays (left, right) for datasets that give only MANO parameters, or
            None when no MANO files are configured.
        keep_mano: the corpus's hand model is that real MANO (keep the datasets' MANO).

    """

    mano: tuple[ManoData, ManoData] | None = None
    keep_mano: bool = False


def _arctic(roots: list[Path], context: AdapterContext) -> Iterator[CorpusSequence]:
    if context.mano is None:
        raise InputError('ARCTIC gives MANO parameters only: set hand_model.mano_dir to the '
                         'folder with MANO_RIGHT.pkl / MANO_LEFT.pkl')
    return iter_arctic(roots, context.mano, context.keep_mano)


def _hot3d(roots: list[Path], context: AdapterContext) -> Iterator[CorpusSequence]:
    if context.mano is None:
        raise InputError('HOT3D hands are MANO parameters (UmeTrack is not supported): set '
                         'hand_model.mano_dir to the folder with MANO_RIGHT.pkl / MANO_LEFT.pkl')
    return iter_hot3d(roots, context.mano, context.keep_mano)


Adapter = Callable[[list[Path], AdapterContext], Iterator[CorpusSequence]]
#: Dataset name -> adapter.
ADAPTERS: Final = MappingProxyType({
    'synthetic': lambda roots, _: iter_synthetic(roots),
    'lerobot': lambda roots, _: iter_lerobot(roots),
    'dexycb': lambda roots, _: iter_dexycb(roots),
    'ho3d': lambda roots, _: iter_ho3d(roots),
    'egodex': lambda roots, _: iter_egodex(roots),
    'arctic': _arctic,
    'hot3d': _hot3d,
})
