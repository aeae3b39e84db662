"""The documentation writes its maths as maths: TeX between dollars, rendered by MathJax
(``docs/conf.py``: ``sphinx.ext.mathjax`` and MyST's ``dollarmath``), not ASCII equations in
code spans. Code spans keep code: function and argument names, calls, values.

The check is a detector of equation-shaped code spans, run over the pages written in TeX; the
detector itself is tested on equations the pages used to hold (it must flag them) and on code
spans they keep (it must not), so that it cannot pass by flagging nothing.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
# Pages whose maths is TeX; a page joins this list once it is converted.
MATH_PAGES = ["index", "ch02", "ch04", "ch05", "ch06", "ch08", "ch09", "ch11", "ch12", "laws",
              "lcp", "lmi", "lti", "orbits", "guide/observers", "guide/controller_design",
              "guide/python_control", "guide/bifurcation"]

# A relation between two sides ...
_RELATION = re.compile(r" (?:=|≤|≥|<=|>=|∈|⪰|⪯|≻|≺|≼|≽|→|⟂|⊥|≈) ")
# ... and a mark that only maths carries: a prime on a symbol (x'), a transpose, an inverse,
# a Greek letter, a norm, an accent (x̂, q̃), Unicode sub/superscripts.
_MATH_MARK = re.compile(r"[A-Za-z)]'|ᵀ|\^T\b|⁻¹|[α-ωΑ-Ω]|‖|[\u0302\u0303\u0304\u0307\u0308]|"
                        r"[₀-₉ᵢⱼₖ⁰-⁹]|[ẋẍ]")
# Code: a string literal, a keyword argument, an attribute, a call of a multi-letter name
# (maths functions such as exp, max, diag are not code), a file.
_MATH_FUNCTIONS = {"exp", "ln", "log", "max", "min", "sin", "cos", "tan", "det", "diag",
                   "sign", "Sign", "sup", "inf", "sat", "eig", "cond", "rank", "tr", "Re",
                   "Im", "sqrt", "abs", "span", "ker", "im", "proj", "companion", "clip"}
_CODE = re.compile(r"[\"']\w|\b\w+=[^=\s]|\b[A-Za-z_]\w*\.[A-Za-z_]|\.py\b")
_CALL = re.compile(r"\b([A-Za-z_][A-Za-z0-9_]{2,})\(")
_SPAN = re.compile(r"(\{[^}\s]+\}`[^`]*`)|(?<!`)`([^`\n]+)`(?!`)")


def is_ascii_equation(span: str) -> bool:
    """Whether the text of a code span is an equation or inequality written in ASCII/Unicode."""
    if not (_RELATION.search(f" {span} ") and _MATH_MARK.search(span)):
        return False
    if _CODE.search(span):
        return False
    return all(m.group(1) in _MATH_FUNCTIONS or "_" not in m.group(1) and len(m.group(1)) < 5
               for m in _CALL.finditer(span))


def _prose(page: str) -> str:
    text = (DOCS / f"{page}.md").read_text()
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)   # code blocks hold code


def _code_spans(text: str) -> list[str]:
    return [m.group(2) for m in _SPAN.finditer(text) if m.group(2)]


# Equations as the pages held them before (they must be caught) ...
RELAPSES = [
    "x_a' = A_a x_a + B_a u",
    "(A - LC)ᵀP + P(A - LC) <= -2αP - εI",
    "V(t) <= e^{-2αt} V(0)",
    "GᵀP = H - KC",
    "y_s = h_sᵀq",
    "b_1 = max_δ ‖e^{(A_a − G_εC_a)δ}‖²",
    "x̂_a' = A_a x̂_a + B_a u + G_ε (y − C_a x̂_a)",
    "τ* = (S Sᵀ)⁻¹ S (∇V(q*) − G_{I*}ᵀ λ*)",
    "0 <= P ⟂ W^T v+ + e W^T v- >= 0",
    "A_iQ + QA_iᵀ + BY + YᵀBᵀ + 2σQ ≼ 0",
    "w ∈ -φ(z)",
    "|s| ≤ √κ(M) |Δ|/γ₁",
]
# ... and code spans the pages keep (they must not be).
KEPT_CODE = [
    "design_lure_observer(plant, alpha=\"max\")",
    "kappa=20",
    "min_dwell = 1e-9",
    "realisation=\"scaled\"",
    "nscontrol run ch02-impact-observer",
    "traj.signal(\"y\")",
    "LureSystem(ss, law)",
    "graph_residual(z, v) <= tol",
    "design_observer(beam, sigma=k·ω_ref, scale=\"auto\")",
    "alpha_max = c/m",
    "state_peak",
]


@pytest.mark.parametrize("span", RELAPSES)
def test_detector_flags_equations_in_code_spans(span):
    assert is_ascii_equation(span)


@pytest.mark.parametrize("span", KEPT_CODE)
def test_detector_spares_code(span):
    assert not is_ascii_equation(span)


def test_detector_reads_spans_as_markdown_does():
    text = "A role {doc}`ch06` then `x' = A x` and `kappa=20`.\n```python\ny = `x' = 1`\n```"
    assert _code_spans(re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)) == [
        "x' = A x", "kappa=20"]


@pytest.mark.parametrize("page", MATH_PAGES)
def test_page_holds_no_ascii_equation_in_code_spans(page):
    found = [s for s in _code_spans(_prose(page)) if is_ascii_equation(s)]
    assert not found, (f"docs/{page}.md writes maths in code spans; write it as $...$ "
                       f"(TeX, rendered by MathJax):\n" + "\n".join(found))


_INLINE = re.compile(r"(?<![\\$])\$(?!\$)(\S(?:[^$\n]*?\S)?)\$(?!\$)")
_DISPLAY = re.compile(r"^\$\$\n(.*?)\n\$\$$", flags=re.S | re.M)


def _maths(page: str) -> list[str]:
    text = _prose(page)
    display = _DISPLAY.findall(text)
    return display + _INLINE.findall(_DISPLAY.sub("", text))


@pytest.mark.parametrize("page", MATH_PAGES)
def test_page_maths_is_tex(page):
    """Balanced groups and environments, and TeX commands instead of the Unicode signs the
    ASCII notation used (MathJax would show those as text glyphs)."""
    maths = _maths(page)
    if page != "index":
        assert len(maths) >= 3, f"docs/{page}.md: expected its maths as $...$"
    for m in maths:
        plain = m.replace(r"\{", "").replace(r"\}", "")
        assert plain.count("{") == plain.count("}"), f"{page}: unbalanced braces in ${m}$"
        assert m.count(r"\begin{") == m.count(r"\end{"), f"{page}: unclosed environment in {m}"
        left = re.findall(r"[ᵀ⁻¹≤≥∈‖⟂⊥⪰≻≺⪯×·→←∞∂∇≡α-ωΑ-Ω\u0302\u0303]", m)
        assert not left, f"{page}: Unicode maths {left} in ${m}$ (use TeX commands)"


def test_mathjax_is_configured():
    conf = (DOCS / "conf.py").read_text()
    assert '"sphinx.ext.mathjax"' in conf and '"dollarmath"' in conf
