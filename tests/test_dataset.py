"""Bench dataset format v1: the loader, its checks and the JSON Schema files."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import jsonschema
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from bench_data_helpers import (
    CORRUPTIONS,
    N_ROWS,
    TRACE_IDS,
    Corruption,
    expected_location,
    folder_fingerprint,
    make_dataset,
    read_json,
    set_cell,
    write_json,
)
from hypothesis import given, settings
from hypothesis import strategies as st

import idtool
from idtool import Dataset, load_dataset
from idtool._data._schema import (
    DATASET_SCHEMA,
    SIMULATOR_PARAMS_SCHEMA,
    TRACE_TABLE_SCHEMA,
    load_schema,
    trace_columns,
)
from idtool._data._table_read import parquet_column
from idtool._errors import IdtoolError


def _problems(path: Path) -> tuple[IdtoolError, list[str]]:
    with pytest.raises(IdtoolError) as info:
        load_dataset(path)
    return info.value, [str(p) for p in info.value.problems]


# --- the example dataset -------------------------------------------------------------


@pytest.fixture(scope="module")
def example() -> Dataset:
    return load_dataset(idtool.example_dataset_path())


def test_example_dataset_loads(example):
    assert example.name == "example-seat-belt-bench"
    assert example.rig.vibration_frequency_hz == 20000.0
    assert example.rig.max_amplitude_m == 85e-6
    assert len(example.traces) == 24
    assert example.warnings == ()
    loads = {t.normal_load_n for t in example.traces}
    assert loads == {270.0, 450.0, 670.0}
    assert {t.amplitude_fraction for t in example.traces} == {0.5, 0.7}
    for trace in example.traces:
        assert trace.sample_rate_hz == pytest.approx(1000.0)
        assert len(trace.on_windows_s) == 1
        start, end = trace.on_windows_s[0]
        assert end - start == pytest.approx(float(trace.id.rpartition("T")[2]), abs=1e-9)
        assert trace.time_s.dtype == np.float64 and trace.ultrasound_on.dtype == np.bool_
        assert np.all(np.diff(trace.time_s) > 0)


def test_example_dataset_is_small_and_has_its_truth():
    root = idtool.example_dataset_path()
    size = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
    assert size < 2_000_000
    truth = json.loads((root / "true_parameters.json").read_text())
    assert truth["dataset_sha256"] == load_dataset(root).sha256


def test_dataset_is_immutable(example):
    trace = example.traces[0]
    for array in (trace.time_s, trace.force_n, trace.ultrasound_on):
        with pytest.raises(ValueError):
            array[0] = array[1]
    with pytest.raises(dataclasses.FrozenInstanceError):
        example.name = "other"  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        trace.normal_load_n = 1.0  # type: ignore[misc]
    assert example.trace(trace.id) is trace
    with pytest.raises(KeyError):
        example.trace("no such trace")


def test_sha256_follows_the_documented_order(tmp_path):
    root = make_dataset(tmp_path / "d")
    digest = hashlib.sha256()
    files = ["dataset.json", *(e["file"] for e in read_json(root)["traces"])]
    for name in files:
        data = (root / name).read_bytes()
        digest.update(len(data).to_bytes(8, "big") + data)
    assert load_dataset(root).sha256 == digest.hexdigest()
    set_cell(root / "traces/b.csv", 3, "force_n", "1.5")
    assert load_dataset(root).sha256 != digest.hexdigest()


def test_path_to_dataset_json_is_accepted(tmp_path):
    root = make_dataset(tmp_path / "d")
    assert load_dataset(root / "dataset.json").sha256 == load_dataset(root).sha256


def test_the_labs_own_fields_are_kept(tmp_path):
    """Top-level ``x_*`` fields reach ``Dataset.extensions`` in file order and survive a
    write and a reload (the report shows them); the models ignore them."""
    root = make_dataset(tmp_path / "d")
    doc = read_json(root)
    doc |= {"x_operator": "J. Doe", "x_batch": {"id": 7, "dyed": True}}
    (root / "dataset.json").write_text(json.dumps(doc))
    ds = load_dataset(root)
    assert list(ds.extensions) == ["x_operator", "x_batch"]
    assert ds.extensions["x_batch"] == {"id": 7, "dyed": True}
    again = load_dataset(idtool.write_dataset(ds, tmp_path / "copy"))
    assert again.extensions == ds.extensions


@pytest.mark.parametrize("bad", ["nowhere", "file.txt", "empty_dir"])
def test_bad_dataset_path(tmp_path, bad):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(IdtoolError, match=bad):
        load_dataset(tmp_path / bad)


# --- CSV and Parquet -----------------------------------------------------------------


def test_parquet_and_csv_give_the_same_trace(tmp_path):
    root = make_dataset(tmp_path / "d")
    csv_trace = load_dataset(root).traces[0]
    table = pa.table(
        {
            "time_s": pa.array(csv_trace.time_s),
            "force_n": pa.array(csv_trace.force_n, pa.float32()).cast(pa.float64()),
            "ultrasound_on": pa.array(csv_trace.ultrasound_on.astype(np.int8)),
        }
    )
    pq.write_table(table, root / "traces/a.parquet")
    document = read_json(root)
    document["traces"][0]["file"] = "traces/a.parquet"
    write_json(root, document)
    parquet_trace = load_dataset(root).traces[0]
    np.testing.assert_array_equal(parquet_trace.time_s, csv_trace.time_s)
    np.testing.assert_allclose(parquet_trace.force_n, csv_trace.force_n, rtol=1e-6)
    np.testing.assert_array_equal(parquet_trace.ultrasound_on, csv_trace.ultrasound_on)
    assert parquet_trace.on_windows_s == csv_trace.on_windows_s


def test_parquet_nulls_and_types_are_located(tmp_path):
    root = make_dataset(tmp_path / "d")
    force = [1.0] * N_ROWS
    force[4] = None
    table = pa.table(
        {
            "time_s": pa.array(np.arange(N_ROWS) / 100.0),
            "force_n": pa.array(force, pa.float64()),
            "ultrasound_on": pa.array(["0"] * 10 + ["maybe"] + ["1"] * (N_ROWS - 11)),
            "stamp": pa.array(np.arange(N_ROWS), pa.timestamp("ms")),
        }
    )
    pq.write_table(table, root / "traces/a.parquet")
    document = read_json(root)
    document["traces"][0]["file"] = "traces/a.parquet"
    write_json(root, document)
    _, problems = _problems(root)
    text = "\n".join(problems)
    assert "a.parquet, row 5, column 'force_n': empty cell" in text
    assert "a.parquet, row 11, column 'ultrasound_on'" in text
    assert "column 'stamp'" in text  # an unknown column is only a warning


@pytest.mark.parametrize(
    "kind", [pa.float64(), pa.float32(), pa.int16(), pa.uint8(), pa.int64(), pa.bool_()]
)
def test_parquet_columns_read_from_their_buffers_match_pyarrow(kind):
    """The fast path (no nulls: the data buffers read directly, without pyarrow's
    pandas-importing conversions) gives pyarrow's own values, for chunked and sliced
    columns (chunks with an offset into their buffers)."""
    rng = np.random.default_rng(0)
    if pa.types.is_boolean(kind):
        values = rng.random(203) < 0.5
    else:
        values = (rng.random(203) * 100).astype(kind.to_pandas_dtype())
    whole = pa.array(values, kind)
    column = pa.chunked_array([whole.slice(3, 50), whole.slice(61, 77), whole.slice(150)])
    expected = np.concatenate([c.to_numpy(zero_copy_only=False) for c in column.chunks])
    raw = parquet_column(column)
    np.testing.assert_array_equal(raw.numbers, expected.astype(float))
    assert not raw.null.any()


@pytest.mark.parametrize(
    "tokens", [("true", "false"), ("1", "0"), ("TRUE", "False"), ("1.0", "0.0")]
)
def test_flag_spellings(tmp_path, tokens):
    root = make_dataset(tmp_path / "d")
    path = root / "traces/a.csv"
    path.write_text(
        path.read_text().replace(",1\n", f",{tokens[0]}\n").replace(",0\n", f",{tokens[1]}\n")
    )
    trace = load_dataset(root).traces[0]
    assert len(trace.on_windows_s) == 1
    assert trace.on_windows_s[0] == pytest.approx((0.2, 0.3))
    assert int(trace.ultrasound_on.sum()) == 10


def test_on_until_the_end_closes_after_the_last_sample(tmp_path):
    root = make_dataset(tmp_path / "d")
    set_cell(root / "traces/a.csv", N_ROWS, "ultrasound_on", "1")
    trace = load_dataset(root).traces[0]
    assert trace.on_windows_s[-1] == pytest.approx((0.59, 0.60))


# --- malformed datasets --------------------------------------------------------------


@pytest.mark.parametrize("case", CORRUPTIONS, ids=lambda c: c.name)
def test_malformed_dataset_gives_a_located_error(tmp_path, case: Corruption):
    root = make_dataset(tmp_path / "d")
    case.apply(root)
    error, problems = _problems(root)
    located = [p for p in problems if all(part in p for part in expected_location(root, case))]
    assert located, f"no problem locates {case}:\n" + "\n".join(problems)
    assert str(root) in error.message or "dataset.json" in error.message


def test_every_problem_in_every_trace_is_reported(tmp_path):
    root = make_dataset(tmp_path / "d")
    cases = [c for c in CORRUPTIONS if c.name in ("text_in_force", "bad_flag", "negative_load")]
    for case in cases:
        case.apply(root)
    _, problems = _problems(root)
    for case in cases:
        parts = expected_location(root, case)
        assert any(all(part in p for part in parts) for p in problems), case.name


def test_repeated_problems_are_listed_then_counted(tmp_path):
    root = make_dataset(tmp_path / "d")
    for row in range(1, 21):
        set_cell(root / "traces/a.csv", row, "force_n", "x")
    _, problems = _problems(root)
    assert sum("'x' is not a number" in p for p in problems) == 5
    assert any("15 more row(s)" in p and "row 6" in p for p in problems)


# --- warnings: legal values in a suspicious unit ----------------------------------------


def _scale_force(root: Path, factor: float) -> None:
    path = root / "traces/a.csv"
    lines = path.read_text().split("\n")
    out = [lines[0]]
    for line in lines[1:]:
        if line:
            t, f, on = line.split(",")
            line = f"{t},{float(f) * factor:.6f},{on}"
        out.append(line)
    path.write_text("\n".join(out))


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (lambda root: _scale_force(root, 1e-3), "multiply it by 1000"),
        (lambda root: _scale_force(root, -1.0), "flip the sign"),
        (lambda root: _scale_force(root, 50.0), "check that force_n is in N"),
        (lambda root: _set(root, 0, "normal_load_n", 0.45), "if it is in kN"),
        (lambda root: _set(root, 1, "pull_speed_m_s", 25), "mm/s"),
        (lambda root: _set_rig(root, "vibration_frequency_hz", 20), "kHz"),
        (lambda root: _set_rig(root, "max_amplitude_m", 85), "µm"),
        (lambda root: set_cell(root / "traces/b.csv", 30, "time_s", "0.295"), "irregular sampling"),
        (lambda root: _set(root, 0, "amplitude_fraction", 0.0), "amplitude_fraction is 0"),
        (
            lambda root: (root / "traces/a.csv").write_text(
                "\n".join(
                    line + (",x" if i else ",temperature_c")
                    for i, line in enumerate((root / "traces/a.csv").read_text().split("\n")[:-1])
                )
            ),
            "not part of format v1",
        ),
    ],
)
def test_suspicious_values_give_warnings(tmp_path, edit, fragment):
    root = make_dataset(tmp_path / "d")
    edit(root)
    dataset = load_dataset(root)
    assert any(fragment in str(w) for w in dataset.warnings), dataset.warnings
    assert all(w.severity == "warning" for w in dataset.warnings)


def _set(root: Path, k: int, field: str, value: object) -> None:
    document = read_json(root)
    document["traces"][k][field] = value
    write_json(root, document)


def _set_rig(root: Path, field: str, value: object) -> None:
    document = read_json(root)
    document["rig"][field] = value
    write_json(root, document)


def test_time_in_ms_warns(tmp_path):
    root = make_dataset(tmp_path / "d")
    path = root / "traces/a.csv"
    lines = path.read_text().split("\n")
    scaled = [lines[0]]
    for line in lines[1:]:
        if line:
            t, rest = line.split(",", 1)
            line = f"{float(t) * 100000:g},{rest}"
        scaled.append(line)
    path.write_text("\n".join(scaled))
    assert any("divide it by 1000" in str(w) for w in load_dataset(root).warnings)


def test_extension_fields_are_allowed(tmp_path):
    root = make_dataset(tmp_path / "d")
    document = read_json(root)
    document["x_operator"] = "someone"
    document["description"] = "bench run"
    document["traces"][0]["notes"] = "first pull"
    document["traces"][0]["x_temperature_c"] = 21.5
    write_json(root, document)
    dataset = load_dataset(root)
    assert dataset.description == "bench run"
    assert dataset.traces[0].notes == "first pull"


# --- property-based: random corruption never escapes as another exception ---------------

_BAD_TOKENS = ("abc", "", " ", "nan", "-inf", "Infinity", "1e999", "0x1F", "1.2.3", "--1", "½")
_TEXT = st.text(
    alphabet=st.characters(exclude_characters='"\r\n', exclude_categories=("Cs",)), max_size=6
)


def _valid_cell(text: str, column: str) -> bool:
    import re

    if column == "ultrasound_on":
        return text.strip().lower() in {"0", "1", "true", "false", "0.0", "1.0"}
    number = r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*"
    return re.fullmatch(number, text, re.ASCII) is not None


def _check_rejected(root: Path) -> None:
    before = folder_fingerprint(root)
    with pytest.raises(IdtoolError) as info:
        load_dataset(root)
    errors = [p for p in info.value.problems if p.severity == "error"]
    assert errors
    assert all(p.file for p in errors)
    assert any(p.row is not None or p.column is not None for p in errors)
    assert folder_fingerprint(root) == before


@settings(max_examples=40, deadline=None)
@given(
    trace=st.sampled_from(["a", "b"]),
    row=st.integers(1, N_ROWS),
    column=st.sampled_from(trace_columns()),
    text=st.one_of(st.sampled_from(_BAD_TOKENS), _TEXT),
)
def test_random_cell_corruption(trace, row, column, text):
    if _valid_cell(text, column):
        text = "abc"
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / "d")
        set_cell(root / f"traces/{trace}.csv", row, column, text)
        _check_rejected(root)


@settings(max_examples=30, deadline=None)
@given(
    trace=st.sampled_from(["a", "b"]),
    column=st.integers(0, 2),
    action=st.sampled_from(["rename", "drop", "duplicate", "truncate"]),
    name=_TEXT.filter(lambda s: "," not in s),
    keep_lines=st.integers(0, 2),
)
def test_random_column_corruption(trace, column, action, name, keep_lines):
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / "d")
        path = root / f"traces/{trace}.csv"
        rows = [line.split(",") for line in path.read_text().split("\n") if line]
        original = rows[0][column]
        if action == "rename":
            rows[0][column] = name if name.strip() != original else original + "x"
        elif action == "drop":
            rows = [r[:column] + r[column + 1 :] for r in rows]
        elif action == "duplicate":
            rows = [[*r, r[column]] for r in rows]
        else:
            rows = rows[:keep_lines]
        path.write_text("\n".join(",".join(r) for r in rows) + ("\n" if rows else ""))
        _check_rejected(root)


_JSON_EDITS = st.one_of(
    st.tuples(
        st.just("trace"),
        st.integers(0, 1),
        st.sampled_from(["normal_load_n", "pull_speed_m_s"]),
        st.sampled_from([-1, 0, -1e-9, "450", None, [], True]),
    ),
    st.tuples(
        st.just("trace"),
        st.integers(0, 1),
        st.just("amplitude_fraction"),
        st.sampled_from([-0.1, 1.5, 50, "0.5", None, {}, False]),
    ),
    st.tuples(
        st.just("trace"),
        st.integers(0, 1),
        st.just("file"),
        st.sampled_from(
            ["../a.csv", "/etc/hosts.csv", "traces/none.csv", "traces\\a.csv", "a.txt", "", 3]
        ),
    ),
    st.tuples(st.just("trace"), st.integers(0, 1), st.just("id"), st.sampled_from(["", 7, None])),
    st.tuples(
        st.just("drop"),
        st.integers(0, 1),
        st.sampled_from(
            ["id", "file", "normal_load_n", "amplitude_fraction", "pull_speed_m_s", "rig", "name"]
        ),
        st.none(),
    ),
    st.tuples(st.just("rename"), st.integers(0, 1), st.sampled_from(["id", "file"]), _TEXT),
    st.tuples(
        st.just("top"), st.just(0), st.just("schema_version"), st.sampled_from(["2", 1, None])
    ),
    st.tuples(
        st.just("top"),
        st.just(0),
        st.sampled_from(["name", "material", "traces", "rig"]),
        st.sampled_from([1, None, [], {"a": 1}]),
    ),
    st.tuples(
        st.just("rig"),
        st.just(0),
        st.sampled_from(["vibration_frequency_hz", "max_amplitude_m"]),
        st.sampled_from([0, -1, "x", None]),
    ),
    st.tuples(st.just("whole"), st.just(0), st.just(""), st.sampled_from([[], "x", 1, None])),
)


@settings(max_examples=50, deadline=None)
@given(edit=_JSON_EDITS)
def test_random_json_corruption(edit):
    kind, k, field, value = edit
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / "d")
        document = read_json(root)
        if kind == "trace":
            document["traces"][k][field] = value
        elif kind == "drop":
            (document if field in ("rig", "name") else document["traces"][k]).pop(field)
        elif kind == "rename":
            entry = document["traces"][k]
            entry[value if value != field else field + "_"] = entry.pop(field)
        elif kind == "top":
            document[field] = value
        elif kind == "rig":
            document["rig"][field] = value
        else:
            document = value
        write_json(root, document)
        _check_rejected(root)


# --- the schema files ------------------------------------------------------------------


@pytest.mark.parametrize("name", [DATASET_SCHEMA, TRACE_TABLE_SCHEMA, SIMULATOR_PARAMS_SCHEMA])
def test_schemas_are_valid_draft_2020_12(name):
    schema = load_schema(name)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)


def test_example_validates_with_plain_jsonschema(example):
    """What another language does: validate the files with the schema alone."""
    root = idtool.example_dataset_path()
    jsonschema.validate(
        json.loads((root / "dataset.json").read_text()), load_schema(DATASET_SCHEMA)
    )
    row_schema = load_schema(TRACE_TABLE_SCHEMA)
    trace = example.traces[0]
    for i in range(0, trace.n_samples, 997):
        row = {
            "time_s": float(trace.time_s[i]),
            "force_n": float(trace.force_n[i]),
            "ultrasound_on": bool(trace.ultrasound_on[i]),
        }
        jsonschema.validate(row, row_schema)
    assert (
        tuple(row_schema["required"]) == trace_columns() == ("time_s", "force_n", "ultrasound_on")
    )


def test_installed_package_finds_schemas_and_example(tmp_path):
    """From another folder, as an installed idtool would be used."""
    code = (
        "import importlib.resources as r, idtool;"
        "names = sorted(p.name for p in r.files('idtool.datasets_schema').iterdir());"
        "print(names); print(idtool.example_dataset_path().is_dir());"
        "print(idtool.load_dataset(idtool.example_dataset_path()).name)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout
    assert "dataset.schema.json" in out and "README.md" in out
    assert "True" in out and "example-seat-belt-bench" in out


def test_loader_writes_nothing(tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(idtool.example_dataset_path(), root)
    before = folder_fingerprint(root)
    load_dataset(root)
    assert folder_fingerprint(root) == before
    assert TRACE_IDS  # the tiny datasets use these ids


def test_each_missing_or_unknown_field_is_its_own_problem(tmp_path):
    root = make_dataset(tmp_path / "d")
    document = read_json(root)
    entry = document["traces"][0]
    entry["fil"] = entry.pop("file")
    entry["normal_lod_n"] = entry.pop("normal_load_n")
    del document["material"]
    write_json(root, document)
    _, problems = _problems(root)
    expected = [
        "column 'material': missing required field 'material'",
        "column 'traces[0].file': missing required field 'file'; is 'fil' a misspelling",
        "column 'traces[0].normal_load_n': missing required field 'normal_load_n'; "
        "is 'normal_lod_n' a misspelling",
        "column 'traces[0].fil': unknown field 'fil': did you mean 'file'?",
        "column 'traces[0].normal_lod_n': unknown field 'normal_lod_n'",
    ]
    for fragment in expected:
        assert sum(fragment in p for p in problems) == 1, fragment
