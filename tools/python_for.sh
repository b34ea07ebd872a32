#!/usr/bin/env bash
# Prints the path of a Python interpreter of version $1 (e.g. 3.13): `python3.13` if one
# runs from PATH, else the newest pyenv install of that version. Exit 1 when there is none.
set -u
v="$1"
if p=$(command -v "python$v" 2>/dev/null) && "$p" -c "import sys; assert sys.version.startswith('$v')" 2>/dev/null; then
	# (a venv's interpreter — PATH may lead to one — gives the one it was made from)
	"$p" -c 'import sys; print(getattr(sys, "_base_executable", None) or sys.executable)'
	exit 0
fi
root=$(pyenv root 2>/dev/null || echo "$HOME/.pyenv")
for d in $(ls -d "$root"/versions/"$v".* 2>/dev/null | sort -V -r); do
	if [ -x "$d/bin/python$v" ]; then
		echo "$d/bin/python$v"
		exit 0
	fi
done
exit 1
