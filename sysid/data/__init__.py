"""Records and files: the :class:`Record` contract, reading and writing data files (``.npz``, ``.csv``, ``.mat``),
model files, JSON, and atomic output.

Everything that touches a file goes through here: readers refuse a bad file with one line naming it, writers
write atomically (a temporary file renamed over the target), so an interrupted command harms nothing.
May import: :mod:`sysid.errors`, :mod:`sysid.config`, :mod:`sysid.registry` (by name, to rebuild a model file).
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.data.io import SUPPORTED_SUFFIXES, check_fs, output_file, read_record, write_record
    from sysid.data.jsonio import json_default, read_json_file
    from sysid.data.modelfile import data_sha256, estimation_info, read_model, write_model
    from sysid.data.record import FS_MAX, FS_MIN, Normaliser, Record, check_array
    from sysid.data.safeio import atomic_path, atomic_write_bytes, atomic_write_text, check_output_path, save_figure

__getattr__, __dir__, __all__ = attach(__name__, __file__)
