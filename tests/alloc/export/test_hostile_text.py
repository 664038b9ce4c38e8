"""Hostile text through the C export (issue 39): names, axes, a vehicle's name and description,
options and prefixes drawn by a seeded generator of what could break out of a C comment
(``*/``, newlines, ``#define``, ``@FIELD@`` markers, backslashes, trigraphs, unicode, NUL, very
long names), exported through the API and through ``alloc export --vehicle FILE``.

Every export is compiled with ``gcc -std=c99 -Wall -Wextra -Werror -pedantic
-fsanitize=address,undefined``; its object's defined global symbols must be exactly the
kernel's public functions for that prefix (``nm``), and its code with the comments removed
(``gcc -fpreprocessed -dD -E``: directives kept, unexpanded) must be byte-identical to the
export of the same problem with plain names, so the macros it defines are the template's
(``gcc -dM``) and a name can change nothing but comment text.  The default run makes
:data:`QUICK` exports; ``-m slow`` runs :data:`LARGE`.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc.export import EXPORTABLE, ExportError, export_c
from alloc.export.text import MAX_PREFIX_CHARS, comment_text

GCC = shutil.which("gcc")
NM = shutil.which("nm")
pytestmark = pytest.mark.skipif(GCC is None or NM is None, reason="gcc and nm are needed to compile and inspect "
                                "the exported kernels")
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-fsanitize=address,undefined", "-O0"]
QUICK, LARGE = 4, 300

#: pieces a hostile name is made of: what ends or opens a comment, starts a directive, splices a
#: line, forms a trigraph, is a template marker or a prefix placeholder, or is not ASCII
PIECES = ["*/", "/*", "//", "\n", "\r\n", "\t", "\\", "\\\n", "??/", "??=", "??(", "?", "*", "/", "@", "@M@",
          "@B@", "@TITLE@", "@EFFECTORS@", "PREFIX_", "PFX_", "#define", "#include <stdio.h>", "#undef K",
          "int injected_{n} = 42;", "#define alloc_qp_allocate not_the_kernel", " ", "'", '"', "%:", "<:", "é",
          "Härkegård", "日本語", "\u0301",
          "\uff0f\uff0a", "\ufe61/", "\u2028", "\x00", "\x1b[2J", "\x7f", "\ud800", "😀", "a", "motor", "x" * 300]


def hostile_text(rng: np.random.Generator, n: int, *, control: bool = True, surrogates: bool = True,
                 limit: int | None = None) -> str:
    """A drawn hostile string (``control=False``: without the control characters a vehicle file
    refuses in a name; ``surrogates=False``: without the lone surrogates it refuses in any text)."""
    def allowed(piece: str) -> bool:
        return ((control or not any(ord(c) < 32 or c == "\x7f" for c in piece))
                and (surrogates or not any(0xD800 <= ord(c) < 0xE000 for c in piece)))

    pieces = [p for p in PIECES if allowed(p)]
    text = "".join(pieces[int(i)] for i in rng.integers(0, len(pieces), size=int(rng.integers(1, 8))))
    text = text.replace("{n}", str(n))
    if rng.random() < 0.05:
        text = text * 200  # very long
    return text[:limit] if limit else text


def _names(rng: np.random.Generator, count: int, seed: int, **kw) -> list[str]:
    out: list[str] = []
    while len(out) < count:
        name = hostile_text(rng, seed, **kw)
        if name.strip() and name not in out:
            out.append(name)
    return out


def _case(seed: int) -> tuple[alloc.Problem, str, dict, str | None, bool]:
    """A small problem, a method, its options, a prefix (None: the default) and the warm start."""
    rng = np.random.default_rng(seed)
    k, m = int(rng.integers(1, 4)), int(rng.integers(2, 6))
    B = rng.standard_normal((k, m))
    problem = alloc.Problem(B, -np.ones(m), np.ones(m), names=_names(rng, m, seed), axes=_names(rng, k, seed))
    method = EXPORTABLE[int(rng.integers(0, len(EXPORTABLE)))]
    options = {"gamma": float(rng.choice([1e-3, 1e-2]))} if method == "wls" else {}
    prefix = None if rng.random() < 0.5 else f"k{seed}_{method}"
    warm = method in ("wls", "qp") and rng.random() < 0.3
    return problem, method, options, prefix, warm


def _plain(problem: alloc.Problem) -> alloc.Problem:
    return problem.replace(names=[f"u{j}" for j in range(problem.m)], axes=[f"v{i}" for i in range(problem.k)])


def _public(kernel) -> set[str]:
    """The defined global symbols a kernel must have: its entry points, no other."""
    names = {f"{kernel.prefix}_allocate", f"{kernel.prefix}_iterations"}
    if kernel.method in ("wls", "qp", "dynamic", "lp"):
        names.add(f"{kernel.prefix}_set_limits")
    if kernel.warm_start:
        names.add(f"{kernel.prefix}_warm_reset")
    return names


def _run(*args: str, cwd) -> str:
    run = subprocess.run(list(args), capture_output=True, text=True, cwd=cwd)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout


def _code(folder, kernel) -> tuple[str, str, set[str]]:
    """The header's and the source's code without comments (directives kept as written), and the
    names of the macros defined after preprocessing."""
    strip = [GCC, "-fpreprocessed", "-dD", "-E", "-P"]
    header = _run(*strip, kernel.header_name, cwd=folder)
    source = _run(*strip, kernel.source_name, cwd=folder)
    macros = {line.split()[1].split("(")[0] for line in _run(GCC, "-std=c99", "-E", "-dM", kernel.source_name,
                                                                  cwd=folder).splitlines()}
    return header, source, macros


def _check(kernel, reference, tmp_path, tag: str) -> None:
    """Compile ``kernel`` under the sanitizers, check its symbols, and its code against the plain
    ``reference`` export's."""
    folder, ref_folder = tmp_path / tag, tmp_path / f"{tag}_ref"
    kernel.write(folder)
    reference.write(ref_folder)
    assert kernel.header.isascii() and kernel.source.isascii()
    obj = folder / "kernel.o"
    _run(GCC, *CFLAGS, "-c", kernel.source_name, "-o", str(obj), cwd=folder)
    defined = set(_run(NM, "-g", "--defined-only", "-j", str(obj), cwd=folder).split())
    assert defined == _public(kernel), sorted(defined ^ _public(kernel))
    assert _code(folder, kernel) == _code(ref_folder, reference)


def _export_api(seed: int, tmp_path) -> None:
    problem, method, options, prefix, warm = _case(seed)
    try:
        kernel = export_c(problem, method, options=options, prefix=prefix, warm_start=warm)
    except ExportError as exc:  # a refusal must be the warm start's (conditioning), named
        assert warm and exc.field == "warm_start", exc
        return
    reference = export_c(_plain(problem), method, options=options, prefix=prefix, warm_start=warm)
    _check(kernel, reference, tmp_path, f"api{seed}")


def _vehicle(problem: alloc.Problem, name: str, description: str) -> dict:
    return {"format": "alloc-vehicle/1", "name": name, "description": description,
            "axes": [{"name": a} for a in problem.axes],
            "effectors": [{"name": n, "kind": "surface", "unit": "rad", "min": -1.0, "max": 1.0}
                          for n in problem.names],
            "effectiveness": {"B": problem.B.tolist()}}


def _export_cli(seed: int, tmp_path) -> None:
    from alloc.cli import app

    rng = np.random.default_rng(10_000 + seed)
    k, m = int(rng.integers(1, 4)), int(rng.integers(2, 6))
    B = rng.standard_normal((k, m))
    # a vehicle file refuses control characters in a name (1-64 characters); the description
    # takes any text
    plain_text = {"control": False, "surrogates": False, "limit": 64}
    named = alloc.Problem(B, -np.ones(m), np.ones(m), names=_names(rng, m, seed, **plain_text),
                          axes=_names(rng, k, seed, **plain_text))
    method = ("pinv", "pinv_scale", "cgi", "qp", "lp")[seed % 5]
    name = hostile_text(rng, seed, control=False, surrogates=False, limit=64) or "v"
    docs = {"hostile": _vehicle(named, name, hostile_text(rng, seed, surrogates=False)),
            "plain": _vehicle(_plain(named), "plain", "")}
    outs = {}
    for tag, doc in docs.items():
        path = tmp_path / f"cli{seed}_{tag}.json"
        path.write_text(json.dumps(doc))
        out = tmp_path / f"cli{seed}_{tag}"
        result = CliRunner().invoke(app, ["export", "--vehicle", str(path), "--method", method, "--out", str(out)])
        assert result.exit_code == 0, result.output
        outs[tag] = out
    kernel = export_c(str(tmp_path / f"cli{seed}_hostile.json"), method)
    assert (outs["hostile"] / kernel.header_name).read_text() == kernel.header
    assert (outs["hostile"] / kernel.source_name).read_text() == kernel.source
    _check(kernel, export_c(str(tmp_path / f"cli{seed}_plain.json"), method), tmp_path, f"cli{seed}")


def _cli_refusal(tmp_path, doc: dict | None, *args: str) -> str:
    """``alloc export`` on ``doc`` (a vehicle file; None: hexa-x) with ``args``: the one stderr
    line of its refusal (exit 2)."""
    from alloc.cli import app

    vehicle = "hexa-x"
    if doc is not None:
        path = tmp_path / "refused.json"
        path.write_text(json.dumps(doc))
        vehicle = str(path)
    result = CliRunner().invoke(app, ["export", "--vehicle", vehicle, *args])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    return lines[0]


def test_cli_refusals_are_one_line(tmp_path):
    rng = np.random.default_rng(3)
    wide = alloc.Problem(rng.standard_normal((3, 20)), -np.ones(20), np.ones(20))
    tall = alloc.Problem(rng.standard_normal((16, 20)), -np.ones(20), np.ones(20))
    out = ["--out", str(tmp_path / "k")]
    assert "error: prefix: " in _cli_refusal(tmp_path, None, "--prefix", "int", *out)
    assert "error: prefix: " in _cli_refusal(tmp_path, None, "--prefix", "a*/\n#define x", *out)
    assert "error: table: " in _cli_refusal(tmp_path, _vehicle(wide, "wide", ""), "--method", "cgi", "--table", *out)
    assert "error: table: " in _cli_refusal(tmp_path, _vehicle(wide, "wide", ""), "--method", "qp", "--table", *out)
    assert "error: iteration_bound: " in _cli_refusal(tmp_path, _vehicle(tall, "tall", ""), "--method", "qp",
                                                      "--certify", *out)
    assert "description: not valid Unicode" in _cli_refusal(tmp_path, _vehicle(wide, "w", "\ud800"), *out)
    assert "name" in _cli_refusal(tmp_path, _vehicle(wide, "a\n#define x", ""), *out)
    (tmp_path / "file").write_text("")
    assert "--out" in _cli_refusal(tmp_path, None, "--out", str(tmp_path / "file"))
    assert not (tmp_path / "k").exists()


def test_hostile_names_through_the_api(tmp_path):
    for seed in range(QUICK):
        _export_api(seed, tmp_path)


def test_hostile_vehicle_files_through_the_cli(tmp_path):
    for seed in range(QUICK // 2):
        _export_cli(seed, tmp_path)


@pytest.mark.slow
def test_hostile_names_large_run(tmp_path):
    for seed in range(LARGE):
        _export_api(1000 + seed, tmp_path)
    for seed in range(LARGE // 3):
        _export_cli(1000 + seed, tmp_path)


# ------------------------------------------------------------------------ prefixes and the escaping

#: refused: keywords, standard headers' names, reserved or non-identifier text, too long
HOSTILE_PREFIXES = ["int", "math", "float", "_x", "__y", "_Bool", "x-y", "é", "x\n", "", "1a",
                    "a" * (MAX_PREFIX_CHARS + 1), "a b", "x;int", "a*/", "static", "while"]
#: accepted, and compiled: the kernel's own internal names (its macros K, M, NL; its constants)
#: as prefixes, whose public names (K_allocate, K_K) still differ from them
INTERNAL_PREFIXES = ["K", "M", "NL", "real", "BM", "UP", "ROUND", "PREFIX", "PFX"]


def _drawn_prefixes(seed: int, count: int) -> list[str]:
    rng = np.random.default_rng(seed)
    alphabet = list("abcXYZ_019") + ["*/", "\n", "é", "#", "@", " "]
    out = HOSTILE_PREFIXES + INTERNAL_PREFIXES
    for _ in range(count):
        out.append("".join(alphabet[int(i)] for i in rng.integers(0, len(alphabet), size=int(rng.integers(1, 12)))))
    return out


def _check_prefixes(prefixes: list[str], tmp_path) -> tuple[int, int]:
    problem = alloc.Problem([[1.0, 2.0, 0.5]], -np.ones(3), np.ones(3))
    accepted = refused = 0
    for i, prefix in enumerate(prefixes):
        method = ("pinv", "qp", "lp")[i % 3]
        try:
            kernel = export_c(problem, method, prefix=prefix)
        except ExportError as exc:
            assert exc.field == "prefix" and str(exc).startswith("prefix: "), exc
            refused += 1
            continue
        accepted += 1
        _check(kernel, export_c(problem, method, prefix=prefix), tmp_path, f"p{i}")
    return accepted, refused


def test_prefixes_are_tokens_or_refused_by_name(tmp_path):
    assert _check_prefixes(HOSTILE_PREFIXES + INTERNAL_PREFIXES, tmp_path) == (len(INTERNAL_PREFIXES),
                                                                               len(HOSTILE_PREFIXES))
    _check_prefixes(_drawn_prefixes(0, 6)[-6:], tmp_path)


@pytest.mark.slow
def test_prefixes_large_run(tmp_path):
    accepted, refused = _check_prefixes(_drawn_prefixes(1, 200), tmp_path)
    assert accepted > 0 and refused > 0


def test_comment_text_leaves_nothing_that_closes_a_comment():
    """The escaping alone, on many drawn strings (no compiler): printable ASCII, no comment
    delimiters, no trigraph start, no '@' or backslash, bounded, and ordinary names unchanged."""
    rng = np.random.default_rng(7)
    for n in range(3000):
        text = comment_text(hostile_text(rng, n))
        padded = f"x{text}x"  # whatever the template puts around it
        assert padded.isascii() and padded.isprintable(), repr(text)
        for bad in ("*/", "/*", "//", "??", "@", "\\"):
            assert bad not in padded, (bad, text)
        assert len(text) <= 11 * 200 + 30  # <U+XXXXX> per character, a space per join
    for plain in ("motor1", "roll", "aileron_l", "hexa-x", "Harkegard (2003), Eq 1.23", "a, b; c=[1, 2]"):
        assert comment_text(plain) == plain
    assert comment_text("Härkegård") == "Harkegard"
