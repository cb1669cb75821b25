"""Reusable transformer parts: attention with qk-norm, rotary embeddings, blocks, patch embeds."""
