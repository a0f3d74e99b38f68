"""Broken YOLO label files never crash the loader: each malformed line is skipped and counted (or, with
``strict``, one DatasetError naming ``file:line``); what is left is exactly the valid boxes.

Label files are generated line by line (hypothesis, derandomised) from known kinds of line, valid or broken, so
the expected boxes and skipped lines are known without parsing: wrong field counts, non-numbers, NaN and inf,
class ids and coordinates out of range, zero sizes, blank lines, CRLF line ends and a byte-order mark. Then
random bytes, the files around the labels (an image without labels, labels without an image, a list naming a
missing image, an unreadable classes.txt) and ``hrlsac dataset info``. The policy is in docs/datasets.md.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from cli_harness import assert_clean_error, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from missions.datasets import YoloDataset
from missions.yolo_labels import MAX_PROBLEMS_KEPT, DatasetError

NAMES = ("person", "boat", "debris")
FUZZ = settings(max_examples=300, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def make_dataset(root: Path, labels: dict[str, str | bytes], images: tuple[str, ...] = ("a",)) -> Path:
    """A folder-layout dataset: images/train/NAME.png (content irrelevant: labels load without opening images),
    labels/train/NAME.txt and classes.txt."""
    (root / "images" / "train").mkdir(parents=True, exist_ok=True)
    (root / "labels" / "train").mkdir(parents=True, exist_ok=True)
    (root / "classes.txt").write_text("\n".join(NAMES) + "\n")
    for name in images:
        (root / "images" / "train" / f"{name}.png").write_bytes(b"not decoded here")
    for name, content in labels.items():
        label = root / "labels" / "train" / f"{name}.txt"
        label.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    return root


# ---------------------------------------------------------------------------------------------- generated lines

UNIT = st.floats(0.0, 1.0)
SIZE = st.floats(1e-6, 1.0)
SEPARATORS = st.sampled_from([" ", "  ", "\t", " \t "])


@st.composite
def valid_line(draw) -> str:
    values = [str(draw(st.integers(0, len(NAMES) - 1))), *(repr(draw(UNIT)) for _ in range(2)),
              *(repr(draw(SIZE)) for _ in range(2))]
    separator = draw(SEPARATORS)
    return draw(st.sampled_from(["", " "])) + separator.join(values) + draw(st.sampled_from(["", " ", "\t"]))


@st.composite
def broken_line(draw) -> str:
    """A line the loader must refuse, with one thing wrong."""
    fields = draw(valid_line()).split()
    problem = draw(st.sampled_from(["too few", "too many", "class text", "class out of range", "not a number",
                                    "not finite", "out of [0, 1]", "zero size"]))
    if problem == "too few":
        fields = fields[:draw(st.integers(1, 4))]
    elif problem == "too many":
        fields += [repr(draw(UNIT)) for _ in range(draw(st.integers(1, 3)))]  # e.g. a confidence column
    elif problem == "class text":
        fields[0] = draw(st.sampled_from(["1.0", "person", "0x1", "one", "-", "1e0"]))
    elif problem == "class out of range":
        fields[0] = str(draw(st.integers(len(NAMES), 10**20) | st.integers(-10**20, -1)))
    elif problem == "not a number":
        fields[draw(st.integers(1, 4))] = draw(st.sampled_from(["abc", "0,5", "1/2", "--1", "0.5.1", "½"]))
    elif problem == "not finite":
        fields[draw(st.integers(1, 4))] = draw(st.sampled_from(["nan", "NaN", "inf", "-inf", "1e999", "-1e999"]))
    elif problem == "out of [0, 1]":
        fields[draw(st.integers(1, 4))] = repr(draw(st.floats(1.0, 1e6, exclude_min=True)
                                                    | st.floats(-1e6, 0.0, exclude_max=True)))
    else:
        fields[draw(st.integers(3, 4))] = draw(st.sampled_from(["0", "0.0", "-0.0"]))
    return " ".join(fields)


BLANK = st.sampled_from(["", " ", "\t", "   "])
LINES = st.lists(st.one_of(valid_line().map(lambda t: ("valid", t)), broken_line().map(lambda t: ("broken", t)),
                           BLANK.map(lambda t: ("blank", t))), max_size=25)


def label_text(lines: list[tuple[str, str]], crlf: bool, bom: bool, final_newline: bool) -> str:
    ending = "\r\n" if crlf else "\n"
    text = ending.join(text for _, text in lines) + (ending if final_newline and lines else "")
    return ("\ufeff" if bom else "") + text


@FUZZ
@given(lines=LINES, crlf=st.booleans(), bom=st.booleans(), final_newline=st.booleans())
def test_lenient_load_keeps_exactly_the_valid_lines(tmp_path, lines, crlf, bom, final_newline):
    root = make_dataset(tmp_path / "ds", {"a": label_text(lines, crlf, bom, final_newline)})
    dataset = YoloDataset(root)
    [item] = dataset.items("train")
    broken = [number for number, (kind, _) in enumerate(lines, start=1) if kind == "broken"]
    assert len(item.boxes) == sum(kind == "valid" for kind, _ in lines)
    assert dataset.stats.skipped_lines == len(broken)
    label = root / "labels" / "train" / "a.txt"
    expected = [f"{label}:{number}:" for number in broken[:MAX_PROBLEMS_KEPT]]
    assert [problem.split(" ", 1)[0] for problem in dataset.stats.problems] == expected
    assert all("\n" not in problem for problem in dataset.stats.problems)


@FUZZ
@given(lines=LINES, crlf=st.booleans(), bom=st.booleans())
def test_strict_load_names_the_first_broken_line(tmp_path, lines, crlf, bom):
    root = make_dataset(tmp_path / "ds", {"a": label_text(lines, crlf, bom, True)})
    broken = [number for number, (kind, _) in enumerate(lines, start=1) if kind == "broken"]
    dataset = YoloDataset(root, strict=True)
    if not broken:
        assert len(dataset.items("train")[0].boxes) == sum(kind == "valid" for kind, _ in lines)
        return
    with pytest.raises(DatasetError) as error:
        dataset.items("train")
    assert str(error.value).startswith(f"{root / 'labels' / 'train' / 'a.txt'}:{broken[0]}: ")
    assert "\n" not in str(error.value)


@FUZZ
@given(content=st.binary(max_size=600))
def test_random_bytes_as_labels_never_crash(tmp_path, content):
    root = make_dataset(tmp_path / "ds", {"a": content})
    dataset = YoloDataset(root)
    [item] = dataset.items("train")
    assert len(item.boxes) + dataset.stats.skipped_lines <= len(content.decode("utf-8", "replace").splitlines())
    try:
        YoloDataset(root, strict=True).items("train")
    except DatasetError as error:
        assert str(error).startswith(str(root / "labels" / "train" / "a.txt")) and "\n" not in str(error)


# ---------------------------------------------------------------------------------------------- fixed cases

@pytest.mark.parametrize("line, problem", [
    ("0 0.5 0.5 0.1", "expected 5 fields 'class cx cy w h', got 4"),
    ("0 0.5 0.5 0.1 0.1 0.9", "expected 5 fields 'class cx cy w h', got 6"),
    ("1.0 0.5 0.5 0.1 0.1", "class id must be an integer, got '1.0'"),
    ("3 0.5 0.5 0.1 0.1", "class id 3 is out of range (the dataset has ids 0, 1, 2)"),
    ("0 nan 0.5 0.1 0.1", "cx must be in [0, 1] (normalised), got 'nan'"),
    ("0 0.5 1.5 0.1 0.1", "cy must be in [0, 1] (normalised), got '1.5'"),
    ("0 0.5 0.5 abc 0.1", "w must be a number, got 'abc'"),
    ("0 0.5 0.5 0.1 0", "w and h must be > 0, got w='0.1' h='0'"),
    ("0 " + "9" * 500 + " 0.5 0.1 0.1", "(502 characters)"),
])
def test_each_problem_is_named(tmp_path, line, problem):
    root = make_dataset(tmp_path, {"a": f"0 0.5 0.5 0.1 0.1\n{line}\n"})
    with pytest.raises(DatasetError) as error:
        YoloDataset(root, strict=True).items("train")
    message = str(error.value)
    assert message.startswith(f"{root / 'labels' / 'train' / 'a.txt'}:2: ") and problem in message, message


def test_byte_order_mark_crlf_and_blank_lines_are_fine(tmp_path):
    # A BOM used to glue onto the first class id ("\ufeff0" is not an integer) and cost the first box.
    root = make_dataset(tmp_path, {"a": "\ufeff0 0.5 0.5 0.1 0.1\r\n\r\n   \r\n1 0.2 0.2 0.1 0.1\r\n"})
    dataset = YoloDataset(root, strict=True)
    assert [box.class_id for box in dataset.items("train")[0].boxes] == [0, 1]


def test_images_and_labels_that_do_not_pair_up(tmp_path):
    root = make_dataset(tmp_path, {"a": "0 0.5 0.5 0.1 0.1\n", "orphan": "0 0.5 0.5 0.1 0.1\n"}, images=("a", "b"))
    dataset = YoloDataset(root, strict=True)  # neither is an error, even in strict mode
    items = {item.stem: item for item in dataset.items("train")}
    assert len(items["a"].boxes) == 1 and items["b"].boxes == ()  # an image without labels shows nothing
    assert dataset.stats.orphan_labels == 1 and dataset.stats.skipped_lines == 0
    assert dataset.stats.problems == [f"{root / 'labels' / 'train' / 'orphan.txt'}: label file without an image; "
                                      "ignored"]
    dataset.items("train")
    assert dataset.stats.orphan_labels == 1  # counted once, however often the split is read


def test_an_image_list_naming_missing_images(tmp_path):
    root = make_dataset(tmp_path, {"a": "0 0.5 0.5 0.1 0.1\n"})
    (root / "train.txt").write_text("images/train/a.png\nimages/train/gone.png\n\n")
    (root / "data.yaml").write_text("train: train.txt\nnames: [person, boat, debris]\n")
    dataset = YoloDataset(root)
    assert [item.stem for item in dataset.items("train")] == ["a"]
    assert dataset.stats.missing_images == 1
    assert dataset.stats.problems == [f"{root / 'train.txt'}:2: listed image {root / 'images/train/gone.png'} "
                                      "not found; left out"]


@pytest.mark.parametrize("file, content, message", [
    ("classes.txt", b"\xff\xfe\x00person", "classes.txt: cannot read"),
    ("data.yaml", b"names: [a\n", "data.yaml: cannot read data.yaml"),
    ("data.yaml", b"- just a list\n", "expected a mapping with train/val/test and names"),
    ("data.yaml", b"train: images/train\nnames: 5\n", "names: expected a list or an {id: name} mapping"),
    ("data.yaml", b"train: images/train\nnames: [a]\nnc: 2\n", "nc is 2 but names lists 1 classes"),
    ("data.yaml", b"train: [images/train, nowhere]\nnames: [a]\n", "train: nowhere not found"),
])
def test_broken_dataset_files_are_one_error(tmp_path, file, content, message):
    root = make_dataset(tmp_path, {})
    (root / file).write_bytes(content)
    with pytest.raises(DatasetError) as error:
        YoloDataset(root)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_dataset_info_reports_what_was_skipped_or_exits_2(tmp_path):
    root = make_dataset(tmp_path / "ds", {"a": "0 0.5 0.5 0.1 0.1\n0 0.5 0.5 0.1\nnot a label\n",
                                          "orphan": ""})
    lenient = run_cli("dataset", "info", str(root))
    assert lenient.code == 0 and "Traceback" not in lenient.err
    assert "skipped: 2 malformed label line(s)" in lenient.out and "1 label file(s) without an image" in lenient.out
    label = root / "labels" / "train" / "a.txt"
    assert f"  {label}:2: expected 5 fields 'class cx cy w h', got 4: '0 0.5 0.5 0.1'" in lenient.out
    assert_clean_error(run_cli("dataset", "info", str(root), "--strict"), f"{label}:2: expected 5 fields")
    (root / "classes.txt").write_bytes(b"\xff\xfe")
    assert_clean_error(run_cli("dataset", "info", str(root)), "classes.txt: cannot read")
