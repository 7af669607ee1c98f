"""``fieldapp keys generate DIR [--name N]``: CURVE key pairs for the base link."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "keys",
        help="make CURVE key pairs for the mobile base link",
        description="Key pairs for the base link (pyzmq certificate files). On the base: "
        "DIR/base.key_secret and DIR/authorized_clients/*.key; on the workstation: "
        "DIR/client.key_secret and DIR/base.key.",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    generate = actions.add_parser(
        "generate", help="write NAME.key (public) and NAME.key_secret (mode 0600) into DIR"
    )
    generate.add_argument("directory", type=Path, metavar="DIR")
    generate.add_argument("--name", default="client", help="'base' or 'client' (default)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from devices.base.errors import KeyFileError
    from devices.base.keys import AUTHORIZED_CLIENTS_DIR, SERVER_KEY_NAME, generate_key_pair

    try:
        public_path, secret_path = generate_key_pair(args.directory, args.name)
    except (KeyFileError, OSError) as error:
        print(f"fieldapp keys: {error}", file=sys.stderr)
        return 1
    print(f"public key: {public_path}")
    print(f"secret key: {secret_path} (mode 0600, never copy it elsewhere)")
    if args.name == SERVER_KEY_NAME:
        print(f"copy {public_path.name} to each workstation's keys folder as {public_path.name}")
    else:
        print(f"copy {public_path.name} into the base's {AUTHORIZED_CLIENTS_DIR}/ folder")
    return 0
