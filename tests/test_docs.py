"""The documentation stays true to the code: README.md and docs/*.md.

- every public name of ``stablemarks`` resolves and is documented;
- the documents point only at files of the repository;
- docs/architecture.md names existing source files, and every function of its equation table imports;
- the README's configuration block loads, and its "Use it from Python" example runs.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import stablemarks as sm
from stablemarks.config import DERIVED, Config, parse_config

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
DOCUMENTS = [README, *sorted((ROOT / "docs").glob("*.md"))]


def section(text: str, heading: str) -> str:
    """The body of the markdown section whose heading line starts with ``heading``, up to the next heading of
    the same or a higher level."""
    m = re.search(rf"^(#+) {re.escape(heading)}.*$", text, re.M)
    assert m, f"no section {heading!r}"
    level = len(m.group(1))
    end = re.search(rf"^#{{1,{level}}} ", text[m.end():], re.M)
    return text[m.end(): m.end() + end.start() if end else len(text)]


def code_blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", text, re.M | re.S)


def resolve(ref: str):
    """Import ``module:qualified.name`` or ``module.function`` (module relative to ``stablemarks``)."""
    if ":" in ref:
        module, qualname = ref.split(":", 1)
        obj = importlib.import_module(f"stablemarks.{module}")
    else:  # the longest importable prefix is the module
        parts = ref.split(".")
        for i in range(len(parts) - 1, 0, -1):
            try:
                obj = importlib.import_module("stablemarks." + ".".join(parts[:i]))
            except ModuleNotFoundError:
                continue
            qualname = ".".join(parts[i:])
            break
        else:
            raise ModuleNotFoundError(f"no module of stablemarks in {ref!r}")
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


# ------------------------------------------------------------------ (a) public names
@pytest.mark.parametrize("name", sm.__all__)
def test_every_public_name_resolves_and_has_a_docstring(name):
    obj = getattr(sm, name)
    if name == "__version__":
        assert isinstance(obj, str) and obj
        return
    doc = obj.__doc__  # its own, not a base class's
    assert doc and doc.strip(), f"stablemarks.{name} has no docstring"
    assert not doc.startswith(f"{name}("), f"stablemarks.{name} has only the dataclass's generated signature"


# ------------------------------------------------------------------ (b) self-contained documents
@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_documents_point_only_at_files_of_the_repository(path):
    text = path.read_text(encoding="utf-8")
    for outside in ("../shared", "DESIGN.md", "paper.md"):
        assert outside not in text, f"{path.name} mentions {outside!r}, which is not in the repository"
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target or target.startswith("mailto:"):
            continue
        assert (path.parent / target).exists(), f"{path.name} links to {target}, which does not exist"


def test_the_readme_cites_the_paper():
    text = " ".join(README.read_text(encoding="utf-8").split())
    for part in ("Inhyuk Moon", "Jun Miura", "Yoshiaki Shirai",
                 "On-line Selection of Stable Visual Landmarks under Uncertainty", "IROS 1999"):
        assert part in text


# ------------------------------------------------------------------ (c) architecture.md against the code
def test_architecture_names_existing_source_files():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    paths = set(re.findall(r"src/stablemarks/[\w/]+\.py", text))
    assert paths, "docs/architecture.md names no source file"
    missing = sorted(p for p in paths if not (ROOT / p).is_file())
    assert missing == []


def equation_table() -> list[dict[str, str]]:
    body = section(ARCHITECTURE.read_text(encoding="utf-8"), "6. Equation → function")
    rows = [line for line in body.splitlines() if line.startswith("|")]
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    out = []
    for line in rows[2:]:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        assert len(cells) == len(header), f"a row of the equation table has {len(cells)} cells: {line}"
        out.append(dict(zip(header, cells, strict=True)))
    return out


def test_the_equation_table_covers_every_equation_and_section():
    table = equation_table()
    covered = set()
    for row in table:
        paper = row["paper"]
        for a, b in re.findall(r"(\d+)(?:[–-](\d+))?", paper.split("Sec")[0]):
            covered |= set(range(int(a), int(b or a) + 1))
        covered |= {f"Sec {s}" for s in re.findall(r"Sec (\d+(?:\.\d+)*)", paper)}
    assert set(range(1, 21)) <= covered, f"equations missing: {sorted(set(range(1, 21)) - covered)}"
    for sec in ("2.1", "2.2", "2.3.4", "2.4", "3.2", "4"):
        assert f"Sec {sec}" in covered, f"section {sec} is not in the table"


def test_every_function_of_the_equation_table_imports():
    refs = [ref for row in equation_table() for ref in re.findall(r"`([^`]+)`", row["implemented in"])]
    assert len(refs) >= 30
    for ref in refs:
        assert re.fullmatch(r"[a-z_][\w.]*(:[A-Za-z_][\w.]*)?", ref), f"not a module:function reference: {ref}"
        obj = resolve(ref)
        assert callable(obj) or isinstance(obj, property), f"{ref} is neither a function, a class nor a property"


def test_the_resolver_rejects_a_wrong_reference():
    with pytest.raises(AttributeError):
        resolve("geometry:StereoCamera.no_such_method")
    with pytest.raises(ModuleNotFoundError):
        resolve("no_such_module:f")
    assert resolve("planes.fit_plane") is resolve("planes:fit_plane")


# ------------------------------------------------------------------ README against the code
def test_the_readme_configuration_block_shows_the_defaults_and_no_derived_setting():
    body = section(README.read_text(encoding="utf-8"), "Configuration (thresholds)")
    import yaml

    (block,) = code_blocks(body, "yaml")
    doc = yaml.safe_load(block)
    parse_config(doc, "README")  # every section and key exists, every value is valid
    defaults = Config()
    for name, values in doc.items():
        for key, value in values.items():
            default = getattr(getattr(defaults, name), key)
            shown = tuple(value) if isinstance(value, list) else value
            assert shown == default, f"README shows {name}.{key}: {value}, the default is {default}"
    assert not any((s, k) in DERIVED for s, keys in doc.items() for k in keys)
    for section_name, key in DERIVED:
        assert f"`{section_name}.{key}`" in body, f"the derived setting {section_name}.{key} is not explained"


@pytest.fixture(scope="module")
def lab_sequence(tmp_path_factory):
    from stablemarks.sim import load_scenario, simulate_run
    from stablemarks.sim.export import write_simulated_sequence

    root = tmp_path_factory.mktemp("readme")
    path = write_simulated_sequence(simulate_run(load_scenario("lab")), root / "results" / "lab-seq", n_frames=3)
    return root, path


def test_the_readme_python_example_runs(lab_sequence, monkeypatch, capsys):
    root, path = lab_sequence
    body = section(README.read_text(encoding="utf-8"), "Use it from Python")
    (code,) = code_blocks(body, "python")
    assert '"results/lab-seq"' in code
    monkeypatch.chdir(root)  # the example writes results/lab-landmarks.yaml
    exec(compile(code.replace('"results/lab-seq"', repr(str(path))), "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert sum("pan_command=" in line for line in lines) == 3
    assert (root / "results" / "lab-landmarks.yaml").is_file()


def _readme_reasons() -> list[str]:
    """The rejection reasons the README lists for ``landmarks.csv``, in its order."""
    text = " ".join(README.read_text(encoding="utf-8").split())
    m = re.search(r"`reason`, for rejected ones, is (.*?);", text)
    assert m, "the README no longer lists the rejection reasons of landmarks.csv"
    return re.findall(r"`([^`]+)`", m.group(1))


def test_the_readme_lists_exactly_the_rejection_reasons_of_the_code():
    from stablemarks import landmarks

    code = {v for k, v in vars(landmarks).items() if k.startswith("REASON_")}
    listed = _readme_reasons()
    assert len(listed) == len(set(listed)), listed
    assert set(listed) == code, (f"README lists {sorted(set(listed) - code)} that the code does not have, and not "
                                 f"{sorted(code - set(listed))}")


def test_the_readme_names_the_on_line_loop_s_own_rejection_reason():
    from stablemarks.localizer import REASON_BOUNDARY_RECHECK

    text = " ".join(README.read_text(encoding="utf-8").split())
    assert f"`{REASON_BOUNDARY_RECHECK}`" in text
