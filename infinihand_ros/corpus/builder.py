"""Build the unified corpus: complete, clean and write sequences into shards, resumably.

Layout under the output directory (see ``docs/corpus_format.md``)::

    shards/shard-NNNNN/<source>.<id>/   one sample directory per kept sequence
    decisions/<source>.<id>.json        the decision on every processed sequence
    manifest.json                       sequences, sources, licences, Stage I / Stage II lists

Each sample directory and decision file appears atomically, so an interrupted build resumes
where it stopped: sequences with a decision are skipped. The shard of a sequence is a stable
hash of its key, so it never moves between runs. The manifest is rebuilt from the decisions.
"""

from collections.abc import Iterable
from dataclasses import dataclass
from dataclasses import field
import json
import logging
from pathlib import Path
from typing import Final
import zlib

from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.config import require_at_least
from infinihand_ros.corpus.adapters.synthetic import SOURCE as SYNTHETIC_SOURCE
from infinihand_ros.corpus.cleaning import clean_sequence
from infinihand_ros.corpus.cleaning import CleaningConfig
from infinihand_ros.corpus.cleaning import KEEP
from infinihand_ros.corpus.cleaning import SequenceLabels
from infinihand_ros.corpus.prepare import complete_sequence
from infinihand_ros.corpus.prepare import PreparedSequence
from infinihand_ros.corpus.sample_writer import sequence_info
from infinihand_ros.corpus.sample_writer import write_sample_directory
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.engine.hands.keypoints import KeypointSource
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import ManoFitConfig
from tqdm import tqdm

logger = logging.getLogger(__name__)

MANIFEST_FILE: Final = 'manifest.json'
MANIFEST_FORMAT: Final = 'infinihand-corpus'
MANIFEST_VERSION: Final = 1
SHARDS_DIR: Final = 'shards'
DECISIONS_DIR: Final = 'decisions'
NOT_CLEANED: Final = 'not cleaned (no 2D source)'
EXACT: Final = 'exact ground truth (not cleaned)'
#: Sources whose labels are exact by construction: cleaning could only remove good data.
EXACT_SOURCES: Final = (SYNTHETIC_SOURCE,)


@dataclass(frozen=True)
class CorpusConfig:
    """Corpus settings (``config/corpus.yaml``, section ``corpus``).

    Attributes:
        num_shards: sequences are spread over this many shard folders.
        min_visible_px: fewer mask pixels mark a hand not visible.

    """

    num_shards: int = 64
    min_visible_px: int = 40

    def __post_init__(self) -> None:
        require_at_least('corpus', 1, num_shards=self.num_shards,
                         min_visible_px=self.min_visible_px)


@dataclass(frozen=True)
class BuildSettings:
    """Everything a build uses besides its inputs."""

    corpus: CorpusConfig = field(default_factory=CorpusConfig)
    mano_fit: ManoFitConfig = field(default_factory=ManoFitConfig)
    cleaning: CleaningConfig = field(default_factory=CleaningConfig)


def sequence_key(sequence: CorpusSequence) -> str:
    """Return ``<source>.<id>``, the sequence's name in the corpus."""
    return f'{sequence.source}.{sequence.sequence_id}'


def shard_name(key: str, num_shards: int) -> str:
    """Return the shard folder of ``key`` (a stable CRC-32 hash)."""
    return f'shard-{zlib.crc32(key.encode()) % num_shards:05d}'


def _decide(prepared: PreparedSequence, source: KeypointSource | None,
            config: CleaningConfig) -> dict:
    """Clean one prepared sequence (or record that no source was given)."""
    sequence, arrays = prepared.sequence, prepared.annotations
    if sequence.source in EXACT_SOURCES:
        return {'decision': KEEP, 'reason': EXACT}
    if source is None:
        return {'decision': KEEP, 'reason': NOT_CLEANED}
    labels = SequenceLabels(sequence.sequence_id, arrays['joints_2d'], arrays['joints_cam'],
                            arrays['box_xyxy'], arrays['visible'])
    detections = [source.detect(sequence.read_rgb(i), i) for i in range(sequence.num_frames)]
    verdict = clean_sequence(labels, detections, config).summary()
    return {'decision': verdict['decision'], 'reason': verdict['reason'],
            'hands': verdict['hands']}


def _process(sequence: CorpusSequence, out: Path, models: tuple[HandModel, HandModel],
             settings: BuildSettings, source: KeypointSource | None) -> None:
    """Complete, clean and (if kept) write one sequence, then record its decision."""
    key = sequence_key(sequence)
    prepared = complete_sequence(sequence, models, settings.mano_fit,
                                 settings.corpus.min_visible_px)
    record = {'key': key, 'frames': sequence.num_frames, **sequence_info(prepared),
              **_decide(prepared, source, settings.cleaning), 'path': None}
    if record['decision'] == KEEP:
        relative = Path(SHARDS_DIR) / shard_name(key, settings.corpus.num_shards) / key
        write_sample_directory(prepared, out / relative)
        record['path'] = str(relative)
    atomic_write_bytes(out / DECISIONS_DIR / f'{key}.json',
                       json.dumps(record, indent=2).encode('utf-8'))


def write_manifest(out: Path) -> dict:
    """Rebuild ``manifest.json`` from the decision files and return it."""
    records = [json.loads(path.read_text(encoding='utf-8'))
               for path in sorted((out / DECISIONS_DIR).glob('*.json'))]
    kept = [r for r in records if r['decision'] == KEEP]
    manifest = {
        'format': MANIFEST_FORMAT, 'version': MANIFEST_VERSION,
        'stage_1': [r['path'] for r in kept],
        'stage_2': [r['path'] for r in kept if r['camera_trajectory']],
        'review': [r['key'] for r in records if r['decision'] == 'review'],
        'discarded': [r['key'] for r in records if r['decision'] == 'discard'],
        'sources': [{'source': name, 'licence': licence} for name, licence
                    in sorted({(r['source'], r['licence']) for r in records})],
        'sequences': records,
    }
    atomic_write_bytes(out / MANIFEST_FILE, json.dumps(manifest, indent=2).encode('utf-8'))
    return manifest


def build_corpus(sequences: Iterable[CorpusSequence], out: Path,
                 models: tuple[HandModel, HandModel], settings: BuildSettings,
                 source: KeypointSource | None = None) -> dict:
    """Process every sequence not yet decided in ``out`` and write the manifest.

    Args:
        sequences: the adapters' sequences (keys must be unique).
        out: corpus directory (created if needed).
        models: hand models (left, right) of the MANO parameters.
        settings: corpus, fitting and cleaning settings.
        source: independent 2D keypoint source for cleaning, or None to keep everything.

    Returns:
        The manifest.

    """
    out = Path(out)
    (out / DECISIONS_DIR).mkdir(parents=True, exist_ok=True)
    done = {path.stem for path in (out / DECISIONS_DIR).glob('*.json')}
    skipped = 0
    for sequence in tqdm(sequences, desc='corpus', unit='seq'):
        if sequence_key(sequence) in done:
            skipped += 1
            continue
        _process(sequence, out, models, settings, source)
    if skipped:
        logger.info('resumed: %d sequence(s) already in %s', skipped, out)
    return write_manifest(out)
