"""What the Python tools in tools/ share: where the kpcn binaries are, argument parsing that
shows the tool's docstring as its help, and checks of files made before any long work.

The binaries are found as the shell tools find them: $KPCN_BIN when set (a build's tools/
folder), else this checkout's build/tools.
"""
import argparse
import math
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def bin_dir():
    """$KPCN_BIN, else this checkout's build/tools."""
    return os.environ.get("KPCN_BIN") or os.path.join(ROOT, "build", "tools")


def tool_path(name):
    """The binary `name` (kpcntool, kpcn-render, ...) under bin_dir()."""
    return os.path.join(bin_dir(), name, name)


def parser(doc):
    """An ArgumentParser whose usage is doc's second paragraph and whose --help prints doc."""
    parts = doc.split("\n\n")
    usage = parts[1].strip()
    if usage.startswith("usage: "):
        usage = usage[len("usage: "):]
    return argparse.ArgumentParser(usage=usage, description=parts[0].strip() + "\n\n" +
                                   "\n\n".join(parts[2:]).strip(),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)


def check_executable(path, what, fail):
    """fail() unless path is an executable regular file."""
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        fail("no %s at '%s' (build first, or set KPCN_BIN or give its option)" % (what, path))


def check_output(path, option, fail):
    """fail() unless a file can be created at path (its folder exists; it is no directory)."""
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path) or not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        fail("%s '%s': cannot write a file there (a directory, or a folder that does not exist "
             "or is not writable)" % (option, path))


def positive_float(text):
    """argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("'%s' is not a number" % text)
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError("'%s' is not a finite number > 0" % text)
    return v
