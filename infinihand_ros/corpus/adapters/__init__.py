"""Adapters from datasets' published layouts to ``CorpusSequence`` objects."""
