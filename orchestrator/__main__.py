"""`python -m orchestrator` and the `railcosim` command (pyproject.toml [project.scripts])."""
import sys


def main() -> None:
    try:
        from orchestrator.cli import entry_point
    except KeyboardInterrupt:   # Ctrl-C while the command loads: nothing has started, nothing is written
        print("railcosim: interrupted before the command started; nothing was written", file=sys.stderr)
        sys.exit(130)
    entry_point()


if __name__ == "__main__":
    main()
