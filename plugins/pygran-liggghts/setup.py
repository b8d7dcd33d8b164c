"""Build of the Thornton-Ning add-on to the installed LIGGGHTS library (metadata: pyproject.toml).

``pygran_liggghts._thornton_ning`` is a plain shared library (loaded with ctypes, not imported)
compiled against Debian's ``libliggghts-dev`` headers (``$PYGRAN_LIGGGHTS_INCLUDE``, else
``/usr/include/liggghts``) and linked to ``libliggghts``; see ``src/pygran_liggghts/addon``.

LIGGGHTS' build generates ``style_<kind>_model.h``, the list of its contact-model headers,
and does not install it: :func:`write_style_headers` writes the same lists from the installed
model headers (each declares its name and identifier), so the identifiers are those the library
was compiled with. The installed ``fix_insert_stream_predefined.h`` is a stub that does not
compile (its base class is undeclared); a header of the same name in the generated folder takes
its place: ``-I-`` makes quoted includes search the listed folders only, that one first. The
fix it declares does not exist in LIGGGHTS-PUBLIC, so the pair loop never reaches it.

Without the headers the package installs without the add-on, and the engine refuses
``ThorntonNing`` saying so.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ADDON = Path("src/pygran_liggghts/addon")
MODEL_KINDS = ("surface", "normal", "tangential", "cohesion", "rolling")
#: Replaces the installed stub (see the module docstring).
INSERT_STREAM_STUB = """\
#include "fix.h"
namespace LAMMPS_NS {
class FixInsertStreamPredefined : public Fix {
public:
    bool has_inserted() const { return false; }
    void copy_history(const int, const int, double* const) const {}
};
}
"""


def liggghts_include() -> Path:
    return Path(os.environ.get("PYGRAN_LIGGGHTS_INCLUDE", "/usr/include/liggghts"))


def mpi_include_dirs() -> list[str]:
    """The MPI compiler wrapper's include folders (Open MPI's, else MPICH's flags)."""
    for command in (["mpicxx", "--showme:incdirs"], ["mpicxx", "-compile_info"]):
        if shutil.which(command[0]) is None:
            continue
        result = subprocess.run(command, capture_output=True, text=True, check=False)
        if result.returncode == 0:
            words = result.stdout.split()
            if command[1] == "--showme:incdirs":
                return words
            return [w[2:] for w in words if w.startswith("-I")]
    return []


def write_style_headers(include: Path, folder: Path) -> None:
    """``style_<kind>_model.h`` for each kind: the installed headers declaring a model of it."""
    folder.mkdir(parents=True, exist_ok=True)
    for kind in MODEL_KINDS:
        declaration = re.compile(rf"^{kind.upper()}_MODEL\(", re.MULTILINE)
        headers = sorted(
            path.name
            for path in include.glob(f"{kind}_model_*.h")
            if declaration.search(path.read_text(errors="replace"))
        )
        text = "".join(f'#include "{name}"\n' for name in headers)
        (folder / f"style_{kind}_model.h").write_text(text)
    (folder / "fix_insert_stream_predefined.h").write_text(INSERT_STREAM_STUB)


class BuildAddon(build_ext):
    """Generates the style headers first; skips the add-on when LIGGGHTS' headers are absent."""

    def build_extensions(self) -> None:
        include = liggghts_include()
        if not (include / "contact_models.h").is_file():
            print(f"pygran-liggghts: no LIGGGHTS headers in {include}; no Thornton-Ning add-on built")
            self.extensions = []
            return
        generated = Path(self.build_temp) / "liggghts-styles"
        write_style_headers(include, generated)
        for extension in self.extensions:
            extension.include_dirs[:0] = [str(generated), str(ADDON)]
            extension.extra_compile_args += ["-I-", f"-I{include}", *(f"-I{d}" for d in mpi_include_dirs())]
        super().build_extensions()


addon = Extension(
    "pygran_liggghts._thornton_ning",
    sources=[str(ADDON / "thornton_ning_pygran.cpp")],
    depends=[str(ADDON / "normal_model_thornton_ning_pygran.h")],
    language="c++",
    define_macros=[("OMPI_SKIP_MPICXX", "1"), ("MPICH_SKIP_MPICXX", "1")],
    extra_compile_args=["-std=c++11", "-O2"],
    libraries=["liggghts"],
)
setup(ext_modules=[addon], cmdclass={"build_ext": BuildAddon})
