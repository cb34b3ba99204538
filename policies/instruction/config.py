"""Instruction-following baseline configuration: camera frames, past positions and the instruction's tokens (no
goal coordinates); a small byte-level text encoder."""

from __future__ import annotations

from dataclasses import dataclass

from policies.config import PolicyConfig


@dataclass
class InstructionConfig(PolicyConfig):
    context: int = 2
    num_waypoints: int = 5
    image_size: tuple[int, int] = (64, 64)
    dim: int = 128                       # token width (frames, past positions, instruction)
    depth: int = 2                       # fusion transformer layers over [frames, past, instruction] tokens
    heads: int = 4
    text_layers: int = 2                 # text encoder layers over the instruction's byte tokens
    max_tokens: int = 256                # instruction bytes read (the env pads them to env.instruction_length)

    def __post_init__(self):
        super().__post_init__()
        if int(self.max_tokens) < 1 or int(self.dim) % int(self.heads):
            raise ValueError(f"InstructionConfig: max_tokens={self.max_tokens} must be >= 1 and dim={self.dim} a "
                             f"multiple of heads={self.heads}")
