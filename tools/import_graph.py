#!/usr/bin/env python3
"""Module-level import graph of the msreg host library, and its upward edges.

Reads every `.rs` file of `host/src` (the library crate `msreg-host`; the `msreg` binary is
its own crate, `cli/`, the top layer, which may import anything), collects the `crate::`
paths each file names (in `use` lines and inline) and the `super::` paths that leave the
file's top-level module, and prints one line per top-level module with the modules it
imports. Each top-level module sits in a layer (below); an import of a module in a higher
layer is an upward edge, printed with the files that make it. Exit status 1 when there is
one, a cycle between two modules (or two submodules of one module), or a library file that
names clap, anyhow or indicatif, or a library manifest (`host/Cargo.toml`) that depends on
them outside its dev-dependencies (command-line code belongs to the binary crate), so
`tools/test.sh` can run it as a check.

    python3 tools/import_graph.py            # graph + upward edges
    python3 tools/import_graph.py --files    # also the file-level edges between modules

Standard library only.
"""
import re
import sys
from pathlib import Path

# Lower layers first. A module may import its own layer and the ones below.
# `report` and `plot` are generic writers (tables, series, images in, files out): every
# layer may write through them, so they sit at the bottom. `sim` renders through the sensor
# models of the algorithm layer (vision's cameras and noise, lidar's scan source, mi's ground
# ray caster), so it sits above it; the pipelines simulate in their studies and tests, and an
# algorithm's own tests that need a simulated scene are integration tests (host/tests/).
LAYERS = [
    ("foundation", ["dataset", "export", "pointcloud", "camera_yaml", "shared_data", "solve", "eval",
                    "report", "plot"]),
    ("algorithms", ["ndt", "vision", "lidar", "mi", "bag"]),
    ("simulation", ["sim"]),
    ("pipelines", ["calibrate", "check", "lidar_camera", "infra", "monitor", "link"]),
]
LAYER_OF = {m: i for i, (_, mods) in enumerate(LAYERS) for m in mods}

# Command-line crates: only the binary crate (cli/) may name them.
BINARY_ONLY = re.compile(r"\b(clap|anyhow|indicatif)::")
CRATE_PATH = re.compile(r"\bcrate::([a-z_][a-z0-9_]*)")
SUPER_PATH = re.compile(r"\b((?:super::)+)([a-z_][a-z0-9_]*)")
USE_GROUP = re.compile(r"\buse\s+crate::\{([^;]*)\};", re.S)


def module_of(path: Path, src: Path) -> list[str]:
    """Module path of a file: host/src/calibrate/lidar_imu/moving.rs -> [calibrate, lidar_imu, moving]."""
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] == "mod":
        parts.pop()
    return parts


def strip_comments(text: str) -> str:
    text = re.sub(r"//[^\n]*", "", text)
    return re.sub(r"/\*.*?\*/", "", text, flags=re.S)


def targets(text: str, module: list[str]) -> set[str]:
    """Top-level modules a file names."""
    out = set(CRATE_PATH.findall(text))
    for group in USE_GROUP.findall(text):
        out.update(re.findall(r"(?:^|[,{\s])([a-z_][a-z0-9_]*)\s*::", group))
    for supers, name in SUPER_PATH.findall(text):
        # `super` of the file module a/b is a; `super::super` from a/b is the crate root.
        if supers.count("super::") == len(module):
            out.add(name)
    return {t for t in out if t in LAYER_OF}


def submodule_targets(text: str, module: list[str]) -> set[str]:
    """Second-level modules of the file's own top module that it names (`top::sub`)."""
    top = module[0]
    out = set(re.findall(rf"\bcrate::{top}::([a-z_][a-z0-9_]*)", text))
    depth = len(module)
    for supers, name in SUPER_PATH.findall(text):
        if supers.count("super::") == depth - 1:
            out.add(name)
    return out


def library_files(src: Path) -> list[Path]:
    """The files of the `lib.rs` tree (the library crate has no binary target)."""
    return sorted(src.rglob("*.rs"))


def manifest_cli_deps(manifest: Path) -> list[str]:
    """Command-line crates in the library manifest's `[dependencies]` table."""
    table, found = "", []
    for line in manifest.read_text().splitlines():
        header = re.match(r"^\[([^\]]+)\]", line)
        if header:
            table = header.group(1)
        elif table == "dependencies":
            name = re.match(r"^([a-z_-]+)\s*=", line)
            if name and name.group(1) in ("clap", "anyhow", "indicatif"):
                found.append(name.group(1))
    return found


def main() -> int:
    root = Path(__file__).resolve().parent.parent
    src = root / "host" / "src"
    show_files = "--files" in sys.argv
    edges: dict[tuple[str, str], list[str]] = {}
    unlayered: set[str] = set()
    sub_edges: set[tuple[str, str]] = set()
    binary_code: dict[str, set[str]] = {}
    for path in library_files(src):
        module = module_of(path, src)
        if module == ["lib"]:
            continue
        top = module[0]
        if top not in LAYER_OF:
            unlayered.add(top)
            continue
        text = strip_comments(path.read_text())
        for crate in BINARY_ONLY.findall(text):
            binary_code.setdefault(crate, set()).add(str(path.relative_to(root)))
        for t in targets(text, module):
            if t != top:
                edges.setdefault((top, t), []).append(str(path.relative_to(root)))
        if len(module) >= 2:
            for t in submodule_targets(text, module):
                if t != module[1]:
                    sub_edges.add((f"{top}::{module[1]}", f"{top}::{t}"))
    print("layers (low to high): " + " < ".join(
        f"{name} ({', '.join(mods)})" for name, mods in LAYERS) + " < binary (crate cli/)")
    for name, mods in LAYERS:
        for m in mods:
            deps = sorted({t for (f, t) in edges if f == m}, key=lambda d: (LAYER_OF[d], d))
            print(f"  {m:<13} -> {', '.join(deps) if deps else '-'}")
    upward = sorted(((f, t) for (f, t) in edges if LAYER_OF[t] > LAYER_OF[f]),
                    key=lambda e: (LAYER_OF[e[0]], e))
    cycles = sorted((f, t) for (f, t) in edges if (t, f) in edges and f < t)
    cycles += sorted((f, t) for (f, t) in sub_edges if (t, f) in sub_edges and f < t)
    if show_files:
        for (f, t), files in sorted(edges.items()):
            print(f"  {f} -> {t}: {', '.join(sorted(set(files)))}")
    print(f"upward edges: {len(upward)}")
    for f, t in upward:
        print(f"  {f} ({LAYERS[LAYER_OF[f]][0]}) -> {t} ({LAYERS[LAYER_OF[t]][0]}): "
              + ", ".join(sorted(set(edges[(f, t)]))))
    print(f"module cycles: {len(cycles)}")
    for f, t in cycles:
        print(f"  {f} <-> {t}")
    print(f"library files naming clap, anyhow or indicatif: {sum(map(len, binary_code.values()))}")
    for crate, files in sorted(binary_code.items()):
        print(f"  {crate}: {', '.join(sorted(files))}")
    manifest_deps = manifest_cli_deps(root / "host" / "Cargo.toml")
    print(f"library [dependencies] on clap, anyhow or indicatif: {len(manifest_deps)}"
          + (f" ({', '.join(manifest_deps)})" if manifest_deps else ""))
    for m in sorted(unlayered):
        print(f"module without a layer (add it to LAYERS): {m}")
    return 1 if upward or cycles or unlayered or binary_code or manifest_deps else 0


if __name__ == "__main__":
    sys.exit(main())
