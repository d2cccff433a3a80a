"""Replay-buffer components for safe RL (samplers stratified by the safety label)."""
