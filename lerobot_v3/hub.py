"""Offline by construction: no LeRobot or Hugging Face call of the chapter reaches for the Hub.

hub_offline() before every LeRobot, datasets or huggingface_hub import of the format (each of them imports
huggingface_hub); OFFLINE_ENV for a LeRobot program started as a subprocess. Nothing is set at import.
"""

from __future__ import annotations

import os
import sys

from ch37.errors import DataError

# What keeps Hugging Face off the network: huggingface_hub's switch and datasets' own. hub_offline sets them
# for its imports only; a LeRobot program started as a subprocess (lerobot-train, lerobot-eval) reads them
# from its environment, so whoever starts one passes them (tests/conftest.py's run_script does).
OFFLINE_ENV = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1"}


def hub_offline() -> None:
    """Offline by construction: every set the chapter reads it made itself, so no LeRobot or Hugging Face
    call may reach for the Hub (a missing local file is an error here, never a download). Called before
    every LeRobot, datasets or huggingface_hub import of ours (tests/test_package_layering.py checks it),
    since any of them imports huggingface_hub. huggingface_hub reads HF_HUB_OFFLINE once, when its
    constants module is first imported, and datasets copies it into datasets.config on its own first
    import, so OFFLINE_ENV is set for those imports only and put back: the process is offline from then
    on, its environment (and so every subprocess's) as it was. Once both are imported, a check of two
    module attributes. If either was imported online before (by you, or by a library outside the
    chapter), this is a DataError: offline or a clear stop, never a fetch."""
    hub, config = sys.modules.get("huggingface_hub.constants"), sys.modules.get("datasets.config")
    if hub is None or config is None:
        saved = {k: os.environ.get(k) for k in OFFLINE_ENV}
        os.environ.update(OFFLINE_ENV)
        try:
            import datasets.config
            import huggingface_hub.constants
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        hub, config = huggingface_hub.constants, datasets.config
    if not (hub.HF_HUB_OFFLINE and config.HF_HUB_OFFLINE):
        raise DataError(
            "huggingface_hub was imported online before the chapter's first LeRobot call; "
            "set HF_HUB_OFFLINE=1 and HF_DATASETS_OFFLINE=1 before importing it (the chapter never downloads)"
        )
