"""Exceptions of crosscal: one class per exit code of the command line.

Every error the library raises is a :class:`CrosscalError` whose message is the one the
command line prints after ``error:`` (the whole cause chain, with file, line and column
where there is one) and whose ``exit_code`` is the code ``crosscal`` would exit with
(``crosscal exit-codes`` lists them). Catch the base class, or the class of one kind::

    try:
        session = crosscal.read_session("unit/session.json")
    except crosscal.errors.BadValueError as e:   # exit code 6
        print(e.exit_code, e)
"""

from __future__ import annotations


class CrosscalError(Exception):
    """A crosscal error: ``str(e)`` is the command line's message, ``e.exit_code`` its code."""

    exit_code: int = 2

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


def _kind(name: str, code: int, doc: str, *bases: type) -> type:
    return type(name, (CrosscalError, *bases), {"exit_code": code, "__doc__": f"Exit code {code}: {doc}."})


AcceptanceFailed = _kind("AcceptanceFailed", 1, "a check or an acceptance rule failed")
UsageError = _kind("UsageError", 2, "a bad argument, or a request these data cannot satisfy", ValueError)
FileError = _kind("FileError", 3, "a file cannot be read or written", OSError)
EmptyRecordingError = _kind("EmptyRecordingError", 4, "no samples, or too few to analyse")
HeaderError = _kind("HeaderError", 5, "header missing, a required column absent or repeated")
BadValueError = _kind("BadValueError", 6, "a value is not a number, or is NaN, infinite or too large", ValueError)
FieldCountError = _kind("FieldCountError", 7, "a row has more or fewer fields than the header")
TimeOrderError = _kind("TimeOrderError", 8, "duplicate or decreasing t (or no usable sample interval)")
TimeGapError = _kind("TimeGapError", 9, "a gap in t (strict mode)")
UnitError = _kind("UnitError", 10, "an unknown or misspelled unit")
JsonError = _kind("JsonError", 11, "a JSON file is not valid JSON or repeats a key")
SessionFormatError = _kind("SessionFormatError", 12, "an unknown session format version")
MissingFileError = _kind("MissingFileError", 13, "a run's file is missing or is not a regular file")
MountError = _kind("MountError", 14, "a mount is not a rotation")
ProfileFormatError = _kind("ProfileFormatError", 15, "a profile of an unknown format version")
WrongUnitError = _kind("WrongUnitError", 16, "a profile of a different unit")
UnidentifiableError = _kind("UnidentifiableError", 17, "the runs cannot identify the requested model (strict)")
ManifestError = _kind("ManifestError", 18, "another invalid manifest value")
MalformedCsvError = _kind("MalformedCsvError", 19, "malformed CSV (quoting, encoding, a line over 1 MiB)")
RulesError = _kind("RulesError", 20, "an invalid rules file")
ProfileError = _kind("ProfileError", 21, "an invalid profile")
EstimateError = _kind("EstimateError", 22, "the estimate failed")
CorrectionError = _kind("CorrectionError", 23, "the correction cannot be made")
OutputExistsError = _kind("OutputExistsError", 24, "the output already exists (crosscal never overwrites)", FileExistsError)
EffectsFileError = _kind("EffectsFileError", 25, "an invalid effects file, or a user effect not finite on the data", ValueError)

BY_CODE: dict[int, type] = {
    c.exit_code: c
    for c in (
        AcceptanceFailed, UsageError, FileError, EmptyRecordingError, HeaderError, BadValueError,
        FieldCountError, TimeOrderError, TimeGapError, UnitError, JsonError, SessionFormatError,
        MissingFileError, MountError, ProfileFormatError, WrongUnitError, UnidentifiableError,
        ManifestError, MalformedCsvError, RulesError, ProfileError, EstimateError, CorrectionError,
        OutputExistsError, EffectsFileError,
    )
}


class OutOfMemoryError(UsageError, MemoryError):
    """Exit code 2: a request these data cannot satisfy in this machine's memory: the memory
    a call needs for its inputs' size was refused (checked before the work starts, so the
    interpreter never aborts on it). Work in blocks (``Streaming.push_block``) or on less."""


class NotFoundError(UsageError, KeyError):
    """Exit code 2: a run, coefficient or other name asked for is not there (a
    :class:`KeyError` too, as a mapping's lookup raises)."""

    def __str__(self) -> str:
        return self.message


def for_code(code: int, message: str) -> CrosscalError:
    """The exception of exit code ``code`` carrying ``message`` (used by the native module)."""
    return BY_CODE.get(code, UsageError)(message)


__all__ = ["CrosscalError", "OutOfMemoryError", "NotFoundError", "for_code", "BY_CODE"] + [c.__name__ for c in BY_CODE.values()]
