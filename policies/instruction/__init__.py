from policies.instruction.config import InstructionConfig
from policies.instruction.model import InstructionPolicy

__all__ = ["InstructionConfig", "InstructionPolicy"]
