"""packaging/install.sh on a small stand-in bundle: the dry run changes nothing, a real install
into a staging root puts every file where it goes, a second run changes nothing more, an
upgrade replaces the app, the uninstall removes it all and keeps the user's data."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

PACKAGING = Path(__file__).resolve().parents[2] / "packaging"
INSTALL = PACKAGING / "install.sh"
RULES = ("60-fieldapp-kinect2.rules", "61-fieldapp-serial.rules")
ICON_FILES = (
    "scalable/apps/fieldapp.svg",
    "48x48/apps/fieldapp.png",
    "128x128/apps/fieldapp.png",
    "256x256/apps/fieldapp.png",
)


def make_bundle(folder: Path, version: str = "9.8.7") -> Path:
    """A stand-in for build/bundle/dist/fieldapp: an executable, _internal/, VERSION."""
    (folder / "_internal").mkdir(parents=True)
    (folder / "_internal" / "library.bin").write_bytes(b"\x00" * 64)
    executable = folder / "fieldapp"
    executable.write_text("#!/bin/sh\necho fieldapp stand-in\n")
    executable.chmod(0o755)
    (folder / "VERSION").write_text(f"{version}\n")
    return folder


def install(*args: str, home: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SUDO_", "XDG_"))}
    if home is not None:
        env["HOME"] = str(home)
    return subprocess.run(
        ["sh", str(INSTALL), *args], capture_output=True, text=True, timeout=60, env=env
    )


def tree(root: Path) -> dict[str, bytes | str]:
    """Every file (its bytes) and symlink (its target) under ``root``."""
    found: dict[str, bytes | str] = {}
    for path in sorted(root.rglob("*")):
        name = str(path.relative_to(root))
        if path.is_symlink():
            found[name] = f"-> {os.readlink(path)}"
        elif path.is_file():
            found[name] = path.read_bytes()
    return found


@pytest.fixture
def bundle(tmp_path: Path) -> Path:
    return make_bundle(tmp_path / "bundle" / "fieldapp")


def system_install(root: Path, bundle: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    done = install("--system", "--root", str(root), "--bundle", str(bundle), *extra)
    assert done.returncode == 0, done.stdout + done.stderr
    return done


def test_dry_run_says_what_it_would_do_and_changes_nothing(tmp_path: Path, bundle: Path) -> None:
    root = tmp_path / "root"
    root.mkdir()
    done = system_install(root, bundle, "--dry-run")
    assert list(root.iterdir()) == []
    out = done.stdout
    assert "dry run: nothing is changed" in out
    assert f"would run: cp -R {bundle} {root}/opt/fieldapp.new" in out
    assert f"would run: ln -sfn /opt/fieldapp/fieldapp {root}/usr/local/bin/fieldapp" in out
    assert f"would write: {root}/usr/local/share/applications/fieldapp.desktop" in out
    for rule in RULES:
        assert f"{root}/etc/udev/rules.d/{rule}" in out


def test_install_puts_app_menu_entry_icon_and_rules_in_place(tmp_path: Path, bundle: Path) -> None:
    root = tmp_path / "root"
    done = system_install(root, bundle)
    app = root / "opt" / "fieldapp"
    assert (app / "fieldapp").read_bytes() == (bundle / "fieldapp").read_bytes()
    assert os.access(app / "fieldapp", os.X_OK)
    assert (app / "_internal" / "library.bin").stat().st_size == 64
    assert "fieldapp 9.8.7" in (app / ".fieldapp-install").read_text()
    assert os.readlink(root / "usr/local/bin/fieldapp") == "/opt/fieldapp/fieldapp"
    desktop = root / "usr/local/share/applications/fieldapp.desktop"
    lines = desktop.read_text().splitlines()
    assert 'Exec="/opt/fieldapp/fieldapp" gui' in lines
    assert "TryExec=/opt/fieldapp/fieldapp" in lines
    assert desktop.stat().st_mode & 0o777 == 0o644
    for icon in ICON_FILES:
        assert (root / "usr/local/share/icons/hicolor" / icon).is_file(), icon
    for rule in RULES:
        installed = root / "etc/udev/rules.d" / rule
        assert installed.read_bytes() == (PACKAGING / "udev" / rule).read_bytes()
        assert installed.stat().st_mode & 0o777 == 0o644
    assert "udev: not reloaded (--root" in done.stdout
    assert f"app: fieldapp 9.8.7 in {app}" in done.stdout
    assert not (root / "opt" / "fieldapp.new").exists()
    assert not (root / "opt" / "fieldapp.old").exists()


@pytest.mark.skipif(shutil.which("desktop-file-validate") is None, reason="no validator")
def test_installed_desktop_entry_validates(tmp_path: Path, bundle: Path) -> None:
    root = tmp_path / "with space"
    system_install(root, bundle, "--prefix", "/opt/field app")
    desktop = root / "usr/local/share/applications/fieldapp.desktop"
    assert 'Exec="/opt/field app/fieldapp" gui' in desktop.read_text()
    done = subprocess.run(["desktop-file-validate", str(desktop)], capture_output=True, text=True)
    assert done.returncode == 0 and not done.stdout.strip(), done.stdout


def test_a_second_install_changes_nothing_and_an_upgrade_replaces_the_app(
    tmp_path: Path, bundle: Path
) -> None:
    root = tmp_path / "root"
    system_install(root, bundle)
    first = tree(root)
    system_install(root, bundle)
    again = tree(root)
    marker = "opt/fieldapp/.fieldapp-install"
    assert {k: v for k, v in again.items() if k != marker} == {
        k: v for k, v in first.items() if k != marker
    }
    newer = make_bundle(tmp_path / "newer" / "fieldapp", version="9.9.0")
    (newer / "_internal" / "library.bin").unlink()
    system_install(root, newer)
    assert (root / "opt/fieldapp/VERSION").read_text() == "9.9.0\n"
    assert not (root / "opt/fieldapp/_internal/library.bin").exists()  # no stale files


def test_user_install_and_uninstall_keep_the_users_data(tmp_path: Path, bundle: Path) -> None:
    home = tmp_path / "home"
    data = home / ".local/share/fieldapp"
    data.mkdir(parents=True)
    (data / "results.sqlite").write_bytes(b"results")
    (data / "calibration.json").write_text("{}")
    config = home / ".config/fieldapp"
    config.mkdir(parents=True)
    (config / "settings.yaml").write_text("devices: {}\n")
    before = tree(home)
    done = install("--user", "--no-udev", "--bundle", str(bundle), home=home)
    assert done.returncode == 0, done.stderr
    assert (home / ".local/lib/fieldapp/fieldapp").is_file()
    assert os.readlink(home / ".local/bin/fieldapp") == f"{home}/.local/lib/fieldapp/fieldapp"
    assert (home / ".local/share/applications/fieldapp.desktop").is_file()
    assert (home / ".local/share/icons/hicolor/scalable/apps/fieldapp.svg").is_file()
    assert "udev: skipped (--no-udev)" in done.stdout
    done = install("--user", "--no-udev", "--uninstall", home=home)
    assert done.returncode == 0, done.stderr
    assert "kept your data" in done.stdout
    after = {k: v for k, v in tree(home).items() if "mimeinfo.cache" not in k}
    assert after == before


def test_system_uninstall_removes_every_installed_file(tmp_path: Path, bundle: Path) -> None:
    root = tmp_path / "root"
    system_install(root, bundle)
    done = install("--system", "--root", str(root), "--uninstall")
    assert done.returncode == 0, done.stderr
    assert tree(root) == {}
    assert f"removed {root}/etc/udev/rules.d/61-fieldapp-serial.rules" in done.stdout


def test_a_folder_that_is_not_an_install_is_never_replaced(tmp_path: Path, bundle: Path) -> None:
    root = tmp_path / "root"
    precious = root / "opt" / "fieldapp" / "thesis.tex"
    precious.parent.mkdir(parents=True)
    precious.write_text("years of work")
    for extra in ((), ("--uninstall",)):
        done = install("--system", "--root", str(root), "--bundle", str(bundle), *extra)
        assert done.returncode == 1
        assert "is not a fieldapp install" in done.stderr
    assert precious.read_text() == "years of work"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--bundle", "/nonexistent/fieldapp"), "--bundle: no folder /nonexistent/fieldapp"),
        (("--frobnicate",), "unknown option: --frobnicate"),
        (("--root", "relative/dir"), "--root must be an absolute path"),
        (("--prefix", "/usr"), "refusing to use /usr as the app folder"),
    ],
)
def test_bad_arguments_are_one_clear_line(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    done = install("--system", "--root", str(tmp_path / "root"), *args)
    assert done.returncode == 1
    assert message in done.stderr
    assert "Traceback" not in done.stderr


def test_a_folder_without_a_bundle_is_refused(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    done = install("--system", "--root", str(tmp_path / "root"), "--bundle", str(empty))
    assert done.returncode == 1
    assert f"no built bundle in {empty}" in done.stderr
