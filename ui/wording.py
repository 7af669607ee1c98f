"""The core's messages in the GUI's words.

The Qt-free core (missions, rig, calibration) ends its advice with the command a terminal user
would run (``fieldapp mission resume SESSION``); a GUI user needs the button instead.
:func:`gui_text` rewrites each command the core names into the control that does the same, and
any command it does not know into a pointer to the window, so no notice tells an operator to
open a terminal.
"""

from __future__ import annotations

import re

REWRITES: list[tuple[str, str]] = [
    (r"resume it \(`fieldapp mission resume [^`]*`\) or choose a new folder",
     "press Resume session... and choose it, or choose a new folder"),
    (r"\(`fieldapp mission resume [^`]*`\)", "(Resume session... on the Mission page)"),
    (r"start one with `fieldapp mission run --out [^`]*`",
     "choose another folder, or press Start for a new mission"),
    (r"\(`fieldapp table --port \S+ unlock` or `home`\)", "(Unlock or Home in Mission > Set-up)"),
    (r"\(`fieldapp table --port \S+ home`\)", "(Home in Mission > Set-up)"),
    (r"\(`fieldapp table --port \S+ confirm`\)", "(It is at its zero mark, in Mission > Set-up)"),
    (r"\(try `fieldapp table --port \S+ status`\)", "(Devices... > Test)"),
    (r"\(try `fieldapp base --endpoint \S+ hello`\)", "(Devices... > Test)"),
    (r"\(try `fieldapp camera info`\)", "(Devices... > Test)"),
    (r"\(`fieldapp calibrate views` and `stations`\)",
     "(Calibrate page: view step and stations)"),
    (r"\(`fieldapp calibrate \.\.\.`\)", "(Calibrate page)"),
    (r"devices\.table_port", "the table's port in Devices..."),
    (r"devices\.base_endpoint/base_keys_dir", "the base's endpoint and key folder in Devices..."),
    (r"devices\.camera_backend", "the camera in Devices..."),
    (r"pip install '?fieldapp\[realsense\]'?", "install fieldapp's RealSense support "
     "(packaging/README.md)"),
    (r", which pip cannot build without the C library: see",
     ", which are installed with the C library: see"),
]  # fmt: skip
ANY_COMMAND = re.compile(r"\(?(?:try )?`fieldapp [^`]*`\)?")


def gui_text(text: str) -> str:
    """``text`` with every command-line instruction replaced by its control in the window."""
    for pattern, replacement in REWRITES:
        text = re.sub(pattern, replacement, text)
    return ANY_COMMAND.sub("(see the Mission and Devices pages)", text)
