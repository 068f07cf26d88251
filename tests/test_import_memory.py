"""`cmsensord import` of a long recording: its memory stays bounded (``--memory-mb``, then one
file) however many files there are, the capture is the same bytes whatever the chunking and
wherever the samples wait, and a disk without room for them is a one-line error that leaves
nothing behind."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cmsensord.importing.errors import ImportFailure
from cmsensord.importing.samples import SampleStore
from processes import peak_rss_mb

FS = 25600


def write_files(d: Path, n: int, seed: int = 0) -> None:
    """``n`` one-second snapshot files of four channels, in g, as .npy."""
    d.mkdir()
    rng = np.random.default_rng(seed)
    for k in range(n):
        np.save(d / f"snap_{k:04d}.npy", 0.1 * rng.standard_normal((FS, 4)))


def import_rss_mb(*args: str | Path, cwd: Path) -> tuple[int, str, float]:
    """(exit status, stderr, peak resident memory in MB) of ``cmsensord import ARGS``."""
    return peak_rss_mb("import", *args, cwd=cwd)


def test_memory_does_not_grow_with_the_number_of_files(tmp_path):
    """With ``--memory-mb 8``, ten times the files (60 of 0.82 MB: 49 MB of float64 samples)
    costs no more than a few MB more memory; holding the recording in memory would cost at
    least 40 MB more."""
    write_files(tmp_path / "short", 6)
    write_files(tmp_path / "long", 60)
    rc, err, short = import_rss_mb("short", "--fs", FS, "--unit", "g", "--memory-mb", "8", "--out", "s.bin",
                                   cwd=tmp_path)
    assert rc == 0, err
    rc, err, long = import_rss_mb("long", "--fs", FS, "--unit", "g", "--memory-mb", "8", "--out", "l.bin",
                                  cwd=tmp_path)
    assert rc == 0, err
    assert "60.00 s of board time from 60 snapshots" in err
    assert long - short < 12, (short, long)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.bin", "l.bin.json", "long", "s.bin",
                                                          "s.bin.json", "short"]


@pytest.mark.parametrize("kind", ["wav", "npy"])
def test_memory_does_not_grow_with_the_length_of_one_file(tmp_path, kind):
    """One 16-bit file of 10 M samples (20 MB; as float64 80 MB) costs at most its own pages (the
    file is mapped, its samples converted a stretch at a time) more than one of 1 M samples."""
    from scipy.io import wavfile

    rng = np.random.default_rng(5)
    for name, n in (("short", 1_000_000), ("long", 10_000_000)):
        x = (rng.standard_normal(n) * 3000).astype(np.int16)
        if kind == "wav":
            wavfile.write(tmp_path / f"{name}.wav", FS, x)
        else:
            np.save(tmp_path / f"{name}.npy", x)
    rss = []
    for name in ("short", "long"):
        rc, err, mb = import_rss_mb(f"{name}.{kind}", "--fs", FS, "--memory-mb", "8", "--out", f"{name}.bin",
                                    cwd=tmp_path)
        assert rc == 0, err
        rss.append(mb)
    assert rss[1] - rss[0] < 20 + 10, rss


def test_memory_does_not_grow_with_the_length_of_one_tdms_file(tmp_path):
    """A TDMS file of 10 M float64 samples in 1-s segments (80 MB) costs at most a few MB more than
    one of 1 M: its channels are read a stretch at a time, not whole (reading it whole cost 2.0 x
    the file); the capture is the same as from the same samples in an NPY file."""
    nptdms = pytest.importorskip("nptdms", reason="the tdms extra")
    rng = np.random.default_rng(6)
    for name, seconds in (("short", 40), ("long", 400)):     # a second at a time: a child process's peak
        npy = np.lib.format.open_memmap(tmp_path / f"{name}.npy", "w+", np.float64, (seconds * FS,))
        with nptdms.TdmsWriter(str(tmp_path / f"{name}.tdms")) as w:   # counts this one's pages at its fork
            for k in range(seconds):
                x = np.round(0.1 * rng.standard_normal(FS), 5)
                w.write_segment([nptdms.ChannelObject("Vibration", "acc", x, {"wf_increment": 1.0 / FS})])
                npy[k * FS:(k + 1) * FS] = x
        npy.flush()
        del npy
    rss = []
    for name in ("short", "long"):
        rc, err, mb = import_rss_mb(f"{name}.tdms", "--unit", "g", "--memory-mb", "8", "--out", f"{name}.bin",
                                    cwd=tmp_path)
        assert rc == 0, err
        rss.append(mb)
    assert rss[1] - rss[0] < 20, rss
    rc, err, _ = import_rss_mb("long.npy", "--fs", FS, "--unit", "g", "--out", "npy.bin", cwd=tmp_path)
    assert rc == 0, err
    assert (tmp_path / "long.bin").read_bytes() == (tmp_path / "npy.bin").read_bytes()


def test_an_npz_array_stored_uncompressed_is_mapped_as_an_npy_file_is(tmp_path):
    """np.savez stores its arrays uncompressed: one of 20 M float64 samples (164 MB) costs the
    import no more than the same array in an .npy file (both mapped; reading it cost 62 MB
    more), and gives the same capture; compressed (np.savez_compressed), it is read, the same."""
    x = np.round(0.1 * np.random.default_rng(1).standard_normal((10_240_000, 2)), 5)
    np.savez(tmp_path / "big.npz", acc=x, fs=25600.0)
    np.save(tmp_path / "big.npy", x)
    np.savez_compressed(tmp_path / "small.npz", acc=x[:256_000], fs=25600.0)
    np.save(tmp_path / "small.npy", x[:256_000])
    del x                                   # a child process's peak counts this one's pages at its fork
    rc, err, npz = import_rss_mb("big.npz", "--unit", "g", "--out", "z.bin", cwd=tmp_path)
    assert rc == 0, err
    rc, err, npy = import_rss_mb("big.npy", "--fs", FS, "--unit", "g", "--out", "y.bin", cwd=tmp_path)
    assert rc == 0, err
    assert npz - npy < 16, (npz, npy)
    assert (tmp_path / "z.bin").read_bytes() == (tmp_path / "y.bin").read_bytes()
    for name, args in (("small.npz", ()), ("small.npy", ("--fs", FS))):
        rc, err, _ = import_rss_mb(name, *args, "--unit", "g", "--out", f"{name}.bin", cwd=tmp_path)
        assert rc == 0, err
    assert (tmp_path / "small.npz.bin").read_bytes() == (tmp_path / "small.npy.bin").read_bytes()


def test_the_capture_is_the_same_bytes_whatever_the_chunk_and_wherever_the_samples_wait(
        tmp_path, monkeypatch):
    """Chunks of one block, of a few blocks and of the default, with the samples in memory, on
    disk from the start, or moved to disk part way, and files converted in stretches of 7 samples
    to the default, give the same capture and sidecar."""
    from cmsensord.cli import main
    from cmsensord.importing import capture_writer, sources

    write_files(tmp_path / "d", 3)
    outs = set()
    for blocks, samples, memory, read in ((1000, 1 << 18, "64", 1 << 18), (7, 1 << 18, "0", 1000),
                                          (1000, 1, "1.5", 1 << 18), (3, 1 << 18, "1.5", 7)):
        monkeypatch.setattr(capture_writer, "CHUNK_BLOCKS", blocks)
        monkeypatch.setattr(capture_writer, "CHUNK_SAMPLES", samples)
        monkeypatch.setattr(sources, "READ_SAMPLES", read)
        out = tmp_path / "o.bin"
        assert main(["import", str(tmp_path / "d"), "--fs", str(FS), "--unit", "g", "--block-len", "2048",
                     "--memory-mb", memory, "--out", str(out)]) == 0
        outs.add((out.read_bytes(), Path(f"{out}.json").read_bytes()))
    assert len(outs) == 1


def test_a_disk_without_room_for_the_samples_is_one_line_and_leaves_nothing(tmp_path, small_fs):
    """With ``--memory-mb 0`` the 512 KiB tmpfs cannot hold one file's 0.82 MB of samples: the
    import says so in one line, exits 2 and leaves the disk as it found it; with the samples in
    memory (the default) the same disk takes the 0.4-MB capture."""
    write_files(tmp_path / "d", 2)
    args = [sys.executable, "-m", "cmsensord", "import", "d", "--fs", str(FS), "--unit", "g", "--out",
            str(small_fs / "o.bin")]
    r = subprocess.run([*args, "--memory-mb", "0"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == (f"cmsensord import: {small_fs}/o.bin: no room on its disk for the samples read so "
                        "far (0.8 MB, 8 bytes a sample a channel, held there until the capture is written): "
                        "No space left on device; free space, give --out on another disk or hold more in "
                        "memory with --memory-mb\n")
    assert list(small_fs.iterdir()) == []
    r = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in small_fs.iterdir()) == ["o.bin", "o.bin.json"]


def test_a_disk_without_room_for_a_long_text_files_numbers_is_one_line_and_leaves_nothing(tmp_path, small_fs):
    """20,000 rows of a time and three channels (640 kB of float64) read in chunks beside an
    --out on the 512 KiB tmpfs: one line, exit 2, the disk as it was."""
    rng = np.random.default_rng(3)
    rows = np.c_[np.arange(20000) / 1000, 0.1 * rng.standard_normal((20000, 3))]
    np.savetxt(tmp_path / "log.csv", rows, fmt="%.4f", delimiter=",", header="t,ax,ay,az", comments="")
    r = subprocess.run([sys.executable, "-m", "cmsensord", "import", "log.csv", "--unit", "g", "--memory-mb", "0",
                        "--out", str(small_fs / "o.bin")], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == (f"cmsensord import: log.csv: no room in {small_fs} for the numbers of this long text file "
                        "(held there while it is read, 8 bytes a value): No space left on device; free space, give "
                        "--out on another disk or hold more in memory with --memory-mb\n")
    assert list(small_fs.iterdir()) == []


def test_an_output_directory_that_does_not_exist_is_one_line(tmp_path):
    write_files(tmp_path / "d", 1)
    r = subprocess.run([sys.executable, "-m", "cmsensord", "import", "d", "--fs", str(FS), "--out",
                        "no/o.bin"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == ("cmsensord import: no/o.bin: cannot write the capture: No such file or directory; "
                        "check that the directory exists, is writable and has room\n")


@pytest.mark.parametrize("memory_mb, on_disk", [(1.0, False), (0.0, True), (0.02, True)])
def test_the_store_reads_back_what_was_appended_and_keeps_each_channel_peak(tmp_path, memory_mb, on_disk):
    """In memory, on disk from the start, or moved there at the third part (past 20 kB)."""
    rng = np.random.default_rng(2)
    parts = [rng.standard_normal((3, n)) for n in (5, 0, 1000, 17)]
    whole = np.concatenate(parts, axis=1)
    with SampleStore(3, str(tmp_path / "o.bin"), memory_mb) as store:
        for x in parts:
            store.append(x)
        assert (store.n_samples, store.on_disk) == (1022, on_disk)
        np.testing.assert_array_equal(store.peak, np.abs(whole).max(axis=1))
        for a, b in ((0, 1022), (3, 9), (1005, 1022), (7, 7)):
            np.testing.assert_array_equal(store.read(a, b), whole[:, a:b])
        for a, b in ((-1, 3), (5, 1023), (9, 8)):
            with pytest.raises(IndexError):
                store.read(a, b)
    assert list(tmp_path.iterdir()) == []


def test_the_store_refuses_a_directory_it_cannot_write(tmp_path):
    with pytest.raises(ImportFailure, match="cannot write the capture: No such file or directory"):
        SampleStore(1, str(tmp_path / "missing" / "o.bin"))


def long_csv(path: Path, dated: bool = False, decimal_comma: bool = False) -> None:
    """A logger's CSV: a preamble, a header, a time (or date and time) column, three channels,
    a comment and a blank line among the rows."""
    rng = np.random.default_rng(2)
    sep, dot = (";", ",") if decimal_comma else (",", ".")
    rows = []
    for k in range(3000):
        t = f"2023-05-01 12:00:{k / 1000:06.3f}" if dated else f"{k / 1000:.3f}".replace(".", dot)
        rows.append(sep.join([t, *(f"{v:.4f}".replace(".", dot) for v in 0.1 * rng.standard_normal(3))]))
    rows[1234:1234] = ["# operator changed the cable", ""]
    path.write_text("Logger: DL-9\nSample rate: see times\n" + sep.join(["Time", "ax", "ay", "az"]) + "\n"
                    + "\n".join(rows) + "\n")


@pytest.mark.parametrize("kind", ["plain", "dated", "decimal_comma"])
def test_a_long_text_file_read_in_chunks_gives_the_same_capture(tmp_path, monkeypatch, kind):
    """Past ``--memory-mb`` a text file's numbers are read a chunk of lines at a time and wait
    on disk; chunks of 1,000 and of 7 lines give the capture and sidecar of a whole read."""
    from cmsensord.cli import main
    from cmsensord.importing import tabular

    long_csv(tmp_path / "log.csv", dated=kind == "dated", decimal_comma=kind == "decimal_comma")
    outs = set()
    for memory, lines in (("64", 1 << 16), ("0", 1000), ("0", 7)):
        monkeypatch.setattr(tabular, "CHUNK_LINES", lines)
        out = tmp_path / "o.bin"
        assert main(["import", str(tmp_path / "log.csv"), "--unit", "g", "--memory-mb", memory, "--out", str(out)]) == 0
        outs.add((out.read_bytes(), Path(f"{out}.json").read_bytes()))
    assert len(outs) == 1
    assert json.loads(Path(f"{out}.json").read_text())["fs"] == 1000


@pytest.mark.parametrize("memory", ["64", "0"])
def test_a_bad_line_of_a_long_text_file_is_named_as_in_a_whole_read(tmp_path, monkeypatch, capsys, memory):
    from cmsensord.cli import main
    from cmsensord.importing import tabular

    monkeypatch.setattr(tabular, "CHUNK_LINES", 3)
    rows = [f"{k},{k % 7}" for k in range(20)]
    (tmp_path / "bad.csv").write_text("t,x\n" + "\n".join(rows[:9] + ["9,oops"] + rows[10:]) + "\n")
    (tmp_path / "wide.csv").write_text("t,x\n" + "\n".join(rows[:13] + ["13,1,2"] + rows[14:]) + "\n")
    for name, line in (("bad", "line 11, column 1: 'oops' is not a number"),
                       ("wide", "line 15: 3 column(s) where the lines before have 2")):
        assert main(["import", str(tmp_path / f"{name}.csv"), "--memory-mb", memory, "--out",
                     str(tmp_path / "o.bin")]) == 2
        assert capsys.readouterr().err == (f"cmsensord import: {tmp_path / name}.csv: {line} (separator ',', a "
                                           "header line); fix the file, or set --separator / --header / --no-header\n")
        assert not list(tmp_path.glob("o.bin*"))


def test_a_blank_line_among_dated_rows_says_nothing_of_numpy(tmp_path):
    from tests.test_import import cmd

    long_csv(tmp_path / "log.csv", dated=True)
    r = cmd("import", "log.csv", "--unit", "g", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0 and "Warning" not in r.stderr and "numpy" not in r.stderr, r.stderr


def test_a_long_text_file_shows_its_progress_while_it_is_read(tmp_path, monkeypatch):
    """One file read in chunks of 500 lines: the bar moves in fractions of it, up to the whole."""
    from cmsensord.cli import main
    from cmsensord.importing import command, tabular

    seen: list[float] = []
    monkeypatch.setattr(tabular, "CHUNK_LINES", 500)
    monkeypatch.setattr(command.Bar, "__call__", lambda self, done: seen.append(done))
    long_csv(tmp_path / "log.csv")
    assert main(["import", str(tmp_path / "log.csv"), "--unit", "g", "--memory-mb", "0",
                 "--out", str(tmp_path / "o.bin")]) == 0
    reading = seen[:seen.index(1.0) + 1]
    assert len(reading) >= 6 and reading == sorted(reading) and 0 < reading[0] < 0.2, reading
