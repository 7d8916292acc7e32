# Shell functions the release scripts share: tests/release/deb and tests/release/build source
# this file. Not a program of its own.

# The workspace's version, from the Cargo.toml in directory $1.
workspace_version() {
  sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' "$1/Cargo.toml"
}

# Installs program $1 as $2, stripped by $3 as dh_strip does: no symbols, no build notes.
install_stripped() {
  install -m 755 "$1" "$2"
  "$3" --remove-section=.comment --remove-section=.note --strip-unneeded "$2"
}

# The newest GLIBC_ symbol version the binaries named need (their glibc floor).
glibc_needed() {
  local file
  for file in "$@"; do objdump -T "$file"; done \
    | grep -o 'GLIBC_[0-9][0-9.]*' | sed 's/GLIBC_//' | sort -Vu | tail -n 1
}
