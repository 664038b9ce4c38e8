"""The only doors from user text to the generated C (:mod:`alloc.export`).

Every string a user controls -- effector and axis names, a vehicle's name and description,
option values, the library's own version and method summaries -- reaches the generated source
as the text of a ``/* ... */`` comment, through :func:`comment_text`, and nowhere else.  The
one user string that becomes C *code* is the prefix of the public names and file names, and it
is accepted only as a validated token (:func:`c_prefix`).  Templates are filled once by
:func:`fill`: one regular-expression pass over the template, the substituted values never
scanned again, so a ``@FIELD@`` marker or a ``PREFIX_`` inside a name stays as it is.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Mapping
from functools import cache
from typing import Any, Union

from .base import ExportError

#: characters of one user text kept in a comment (the rest is cut, saying so): a name is
#: 64 at most in a vehicle file, a description a sentence
MAX_COMMENT_CHARS = 200
#: characters of a prefix: C99 keeps 31 significant initial characters of an external name
#: (5.2.4.1), and the prefix alone must be distinct within that
MAX_PREFIX_CHARS = 31

#: C99's keywords (6.4.1): a prefix must not be one
C_KEYWORDS = frozenset("""auto break case char const continue default do double else enum extern float for goto
    if inline int long register restrict return short signed sizeof static struct switch typedef union unsigned
    void volatile while _Bool _Complex _Imaginary""".split())
#: C99's standard headers (7.1.2): a prefix names the kernel's header file, and a ``math.h`` of
#: its own would stand in for the library's under ``-I.``
C_HEADERS = frozenset("""assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal
    stdarg stdbool stddef stdint stdio stdlib string tgmath time wchar wctype""".split())
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: where a comment could end, open, or be read as a trigraph: ``*/``, ``/*``, ``//``, ``??``
_JOINS = re.compile(r"(?<=\*)(?=/)|(?<=/)(?=[*/])|(?<=\?)(?=\?)")
#: line breaks and other white space runs
_SPACE = re.compile(r"\s+")
_EDGE = "*/?"


class Comment(str):
    """Text made safe for a C comment by :func:`comment_text` (the only constructor)."""


def comment_text(value: Any, limit: int = MAX_COMMENT_CHARS) -> Comment:
    """``value`` as text that can stand anywhere inside a C ``/* ... */`` comment.

    Unicode is decomposed (NFKD) and its combining marks dropped, so ``"Härkegård"`` reads
    ``"Harkegard"``; white space runs, newlines included, become one space; a character that is
    not printable ASCII, and ``\\`` (a line splice at a line's end) and ``@`` (the templates'
    markers), become ``<U+XXXX>``; ``*/``, ``/*``, ``//`` and ``??`` (a trigraph's start) get a
    space between their characters, and a ``*``, ``/`` or ``?`` at either end one outside it,
    so that nothing the template puts next to the text joins it into one.  Beyond ``limit``
    characters (after the decomposition) the text is cut, saying so: at most ``11 limit + 30``
    characters come out.  Printable ASCII names without
    those pairs are unchanged.
    """
    text = str(value)[:4 * limit]  # bounds the normalisation's work
    # NFKD before the escaping: a decomposition can make "*" or "/" of other characters (U+FF0F)
    text = "".join(ch for ch in unicodedata.normalize("NFKD", text) if not unicodedata.combining(ch))
    cut = len(text) > limit or len(str(value)) > 4 * limit
    text = text[:limit]
    text = _SPACE.sub(" ", text)
    text = "".join(ch if " " <= ch <= "~" and ch not in "\\@" else f"<U+{ord(ch):04X}>" for ch in text)
    text = _JOINS.sub(" ", text)
    if cut:
        text += f" ... (cut at {limit} characters)"
    if text[:1] in _EDGE and text:
        text = " " + text
    if text[-1:] in _EDGE and text:
        text += " "
    return Comment(text)


def c_prefix(value: Any, field: str = "prefix") -> str:
    """``value`` if it can prefix the kernel's C names and files, else :class:`ExportError`
    naming ``field``: an ASCII C identifier (``[A-Za-z_][A-Za-z0-9_]*``) of at most
    :data:`MAX_PREFIX_CHARS` characters, not a keyword, not a standard header's name, not
    in a family of names reserved to the C implementation."""
    if not isinstance(value, str):
        raise ExportError(f"{field}: expected a C identifier, got {type(value).__name__}", field=field)
    shown = ascii(value[:40])  # an error message, not C: escapes, never transliterates
    if not _IDENTIFIER.fullmatch(value):
        raise ExportError(f"{field}: expected a C identifier ([A-Za-z_][A-Za-z0-9_]*), got {shown}", field=field)
    if len(value) > MAX_PREFIX_CHARS:
        raise ExportError(f"{field}: at most {MAX_PREFIX_CHARS} characters (C99's significant length of an "
                          f"external name), got {len(value)}", field=field)
    if value in C_KEYWORDS or value.lower() in C_HEADERS:
        raise ExportError(f"{field}: {value!r} is a C keyword or a standard header's name", field=field)
    if value.startswith("_"):  # _X... and __... are the implementation's (C99 7.1.3)
        raise ExportError(f"{field}: {value!r} starts with an underscore (names reserved to the C implementation)",
                          field=field)
    taken = sorted(public_names(value) & _template_names())
    if taken:
        raise ExportError(f"{field}: {value!r} would make {taken[0]}, a name the kernel's source already uses",
                          field=field)
    return value


#: the suffixes of the kernel's public names (``PREFIX_``) and macros (``PFX_``)
PUBLIC_SUFFIXES = ("allocate", "iterations", "set_limits", "warm_reset", "real")
MACRO_SUFFIXES = ("H", "K", "M", "VMAX", "EXACT_RTOL", "MAXIT", "MAXIT_TOTAL", "ITERATION_BOUND")


def public_names(prefix: str) -> set[str]:
    """The names a kernel with ``prefix`` defines outside its own file (its header's)."""
    upper = prefix.upper()
    return {f"{prefix}_{s}" for s in PUBLIC_SUFFIXES} | {f"{upper}_{s}" for s in MACRO_SUFFIXES}


@cache
def _template_names() -> frozenset[str]:
    """Every identifier the templates use besides the prefixed ones (their own names and the C
    library's: ``FLT_MAX``, ``sqrt``, ``NULL``): a public name must differ from all."""
    from . import templates, templates_active_set, templates_cascade, templates_closed_form, templates_simplex

    modules = (templates, templates_active_set, templates_cascade, templates_closed_form, templates_simplex)
    text = "\n".join(v for mod in modules for key, v in vars(mod).items()
                     if isinstance(v, str) and not key.startswith("__"))
    text = re.sub(r"(PREFIX|PFX)_\w+", " ", text)
    return frozenset(_IDENTIFIER.findall(text)) | C_KEYWORDS



#: a field value: code the generator made, a :class:`Comment`, or a sequence of both
Field = Union[str, Comment, tuple]
_MARKER = re.compile(r"@([A-Z][A-Z0-9_]*)@|PREFIX_|PFX_")
#: what generated code may hold: printable ASCII and newlines, no marker character
_CODE = re.compile(r"[ -?A-~\n]*")


def _code(key: str, value: str, lower: str, upper: str) -> str:
    """Code the generator made (numbers, tables, its own comments): its ``PREFIX_`` and
    ``PFX_`` names given the prefix; refused (an internal error) if it holds what only user
    text could bring."""
    if not _CODE.fullmatch(value):
        raise RuntimeError(f"export template field {key}: generated code holds a character outside printable "
                           "ASCII or an '@' (user text must come through comment_text)")
    return value.replace("PREFIX_", lower).replace("PFX_", upper)


def _value(key: str, value: Field, lower: str, upper: str) -> str:
    if isinstance(value, Comment):
        return str(value)
    if isinstance(value, tuple):
        return "".join(_value(key, part, lower, upper) for part in value)
    if not isinstance(value, str):
        raise TypeError(f"export template field {key}: expected text, got {type(value).__name__}")
    return _code(key, value, lower, upper)


def fill(template: str, fields: Mapping[str, Field], prefix: str) -> str:
    """The template with every ``@NAME@`` replaced by its field and ``PREFIX_`` / ``PFX_`` by the
    kernel's lower- and upper-case prefix, in one pass: a value is never scanned again.

    A :class:`Comment` value is placed as it is; any other string is the generator's own code
    (checked: printable ASCII, no ``@``; its ``PREFIX_`` names given the prefix once, before
    it is placed).  A marker without a field is an internal error.
    """
    lower, upper = prefix + "_", prefix.upper() + "_"
    values = {key: _value(key, value, lower, upper) for key, value in fields.items()}

    def one(match: re.Match[str]) -> str:
        key = match.group(1)
        if key is None:
            return lower if match.group(0) == "PREFIX_" else upper
        if key not in values:
            raise RuntimeError(f"export template: no field for marker @{key}@")
        return values[key]

    text = _MARKER.sub(one, template)
    if not text.isascii():  # the templates are ASCII: C99's source character set
        raise RuntimeError("export template: non-ASCII text in a template")
    return text
