"""Reading and writing: Oxford VGG sequences (:mod:`.oxford`), the JSON problem files of
``tritools solve`` (:mod:`.problem_file`) and COLMAP models (:mod:`.colmap`)."""
from .oxford import (DATA_ENV, PAPER_SEQUENCES, SEQUENCES, DataNotFoundError, Sequence, Track, data_dir,
                     load_sequence)
from .problem_file import ProblemFileError, ProblemSpec, load_problem_file, parse_problem_text

__all__ = ["DATA_ENV", "PAPER_SEQUENCES", "SEQUENCES", "DataNotFoundError", "Sequence", "Track", "data_dir",
           "load_sequence", "ProblemFileError", "ProblemSpec", "load_problem_file", "parse_problem_text"]
