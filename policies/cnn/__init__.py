"""Small CNN baseline: fast enough for tests and CPU smoke runs."""

from policies.cnn.config import CNNConfig
from policies.cnn.model import CNNPolicy

__all__ = ["CNNConfig", "CNNPolicy"]
