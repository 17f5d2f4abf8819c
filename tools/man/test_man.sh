#!/bin/sh
# The man pages kept honest (issue 18), run by make check as build/tests/test_man: for every
# program and subcommand, each long option its --help prints is in its page and each option its
# page defines (a .TP tag) is in its --help; every page renders without a warning (man
# --warnings, as lintian runs it, and groff -ww); every program the build makes, every command of
# `stillheart --help` and every key of `stillheart run --print-config` has its page; no page
# points to a stillheart page that is not there. The pages are the build's ($(BUILD)/man, made
# by `make man` from man/). Prints cmocka-style summary lines.
B=${BUILD:-$(dirname "$(readlink -f "$0")")/..}
M=$B/man
T=$(mktemp -d /tmp/sh-man-test.XXXXXX)
trap 'rm -rf "$T"' EXIT
passed=0; failed=0
result() { # result NAME: OK when $T/fail is empty, else FAILED with its lines
    if [ -s "$T/fail" ]; then
        echo "[  FAILED  ] $1: $(tr '\n' ';' < "$T/fail")"; failed=$((failed + 1))
    else echo "[       OK ] $1"; passed=$((passed + 1)); fi
    : > "$T/fail"
}
: > "$T/fail"
# Help texts that do not list an option their page rightly documents, "NAME OPTION" a line (only
# these pairs are let through): none today, every --help lists all its options.
KNOWN_MISSING_FROM_HELP=""

# troff source as text: \- is '-', font escapes dropped, the arguments of the alternating font
# macros (.BI \-\-camera N \-KEY) joined as troff joins them
plain() {
    sed -e 's/\\-/-/g' -e 's/\\f[BIRP]//g' -e 's/\\(en/-/g' -e 's/\\&//g' "$@" | awk '
    /^\.(BI|BR|IB|IR|RB|RI) / {
        s = substr($0, 5); out = ""
        while (length(s)) {
            if (substr(s, 1, 1) == "\"") { e = index(substr(s, 2), "\""); if (!e) e = length(s)
                out = out substr(s, 2, e - 1); s = substr(s, e + 2) }
            else { e = index(s, " "); if (!e) e = length(s) + 1; out = out substr(s, 1, e - 1); s = substr(s, e) }
            sub(/^ +/, "", s)
        }
        print substr($0, 1, 4) out; next
    }
    { print }'
}
longopts() { grep -oE -- '--[A-Za-z0-9][A-Za-z0-9-]*' | sed 's/-*$//' | sort -u; }
# the options a page defines: those on the tag line after each .TP
tagopts() { plain "$@" | awk 'tp { print; tp = 0 } /^\.TP/ { tp = 1 }' | longopts; }
has() { grep -qE -- "(^|[^A-Za-z0-9-])$1([^A-Za-z0-9-]|\$)" "$2"; }

# check_help NAME PAGE... : NAME's --help (NAME is a program of $B, with a subcommand maybe)
check_help() {
    name=$1; shift
    prog=$(echo "$name" | cut -d' ' -f1); sub=$(echo "$name" | cut -s -d' ' -f2)
    if [ ! -x "$B/$prog" ]; then echo "[       OK ] $name: not built here, skipped"; return; fi
    # stillheart-trackeval prints its usage on stderr for any unknown argument, --help too
    "$B/$prog" $sub --help > "$T/help" 2>&1
    for p in "$@"; do [ -s "$M/$p" ] || echo "no page $M/$p" >> "$T/fail"; done
    if [ ! -s "$T/fail" ]; then
        (cd "$M" && plain "$@") > "$T/page"
        for o in $(longopts < "$T/help"); do
            has "$o" "$T/page" || echo "$o (in --help) not in $*" >> "$T/fail"
        done
        for o in $(cd "$M" && tagopts "$@"); do
            echo "$KNOWN_MISSING_FROM_HELP" | grep -qFx -- "$name $o" && continue
            has "$o" "$T/help" || echo "$o (defined in $*) not in --help" >> "$T/fail"
        done
    fi
    result "$name: the options of --help and of $* agree"
}

check_help stillheart stillheart.1
for c in $("$B/stillheart" --help | awk '/^commands:/ { on = 1; next } on && /^  [a-z]/ { print $1 }'); do
    [ -s "$M/stillheart-$c.1" ] || echo "no page stillheart-$c.1" >> "$T/fail"
    grep -q "^\.B $c\$" "$M/stillheart.1" || echo "stillheart.1 does not list $c" >> "$T/fail"
    echo "$c" >> "$T/commands"
done
[ -s "$T/commands" ] || echo "no commands in stillheart --help" >> "$T/fail"
result "every command of stillheart --help has its page and is in stillheart.1"
for c in $(cat "$T/commands"); do
    if [ "$c" = run ]; then check_help "stillheart run" stillheart-run.1 stillheart.ini.5
    else check_help "stillheart $c" "stillheart-$c.1"; fi
done

# every program of the build but the QEMU guest's probe (tools/capture, never installed)
for p in "$B"/stillheart-*; do
    n=$(basename "$p")
    [ -x "$p" ] && [ -f "$p" ] && [ "$n" != stillheart-vmprobe ] || continue
    echo "$n" >> "$T/programs"
    check_help "$n" "$n.1"
done
[ -s "$T/programs" ] || echo "no stillheart-* program in $B" >> "$T/fail"
result "the build's programs found ($(cat "$T/programs" 2>/dev/null | tr '\n' ' '))"

# every page: its .TH names its file and the version `stillheart --version` prints, no warning
# from man or groff
ver=$("$B/stillheart" --version | awk '{print $NF}')
for f in "$M"/*.[1-8]; do
    n=$(basename "$f"); sec=${n##*.}; title=$(echo "${n%.*}" | tr a-z A-Z)
    plain "$f" | grep -q "^\.TH \"*$title\"* $sec " || echo "$n: .TH is not '$title $sec'" >> "$T/fail"
    grep -q "^\.TH .*\"stillheart $ver\"" "$f" || echo "$n: .TH does not carry version '$ver'" >> "$T/fail"
    if command -v man > /dev/null; then
        w=$(LC_ALL=C.UTF-8 MANWIDTH=80 man --warnings -E UTF-8 -l -Tutf8 -Z "$f" 2>&1 > /dev/null)
        [ -z "$w" ] || echo "$n: man: $w" >> "$T/fail"
    fi
    if command -v groff > /dev/null; then
        w=$(groff -man -Tutf8 -ww -z "$f" 2>&1)
        [ -z "$w" ] || echo "$n: groff: $w" >> "$T/fail"
    else echo "$n: groff missing (apt-get install groff-base)" >> "$T/fail"; fi
    # cross references to stillheart pages: .BR stillheart\-x (1)
    for r in $(plain "$f" | sed -n 's/^\.BR \(stillheart[^ (]*\) *(\([1-8]\)).*/\1.\2/p'); do
        [ -s "$M/$r" ] || echo "$n: refers to $r, which is not there" >> "$T/fail"
    done
    echo "$n" >> "$T/pages"
done
[ -s "$T/pages" ] || echo "no pages in $M (make man)" >> "$T/fail"
result "every page renders without warnings, names itself and refers to pages that exist"

# stillheart.ini(5) holds every section and key the daemon prints as its config
"$B/stillheart" run --camera1-spec y4m:/nonexistent.y4m --print-config > "$T/config" 2>&1 ||
    echo "stillheart run --print-config failed: $(tail -1 "$T/config")" >> "$T/fail"
plain "$M/stillheart.ini.5" > "$T/ini"
sec=""
while IFS= read -r l; do
    case "$l" in
    "[camera"[0-9]"]") sec=$l
        grep -q '^\.SS \[camera0\] \.\. \[camera3\]' "$T/ini" || echo "no [cameraN] section in stillheart.ini.5" >> "$T/fail" ;;
    "["*"]") sec=$l
        grep -qF ".SS $sec" "$T/ini" || echo "section $sec not in stillheart.ini.5" >> "$T/fail" ;;
    *" = "*|*" =") k=${l%% =*}
        grep -qE "^\.BR? $k( |\$)" "$T/ini" || echo "$sec $k not in stillheart.ini.5" >> "$T/fail" ;;
    esac
done < "$T/config"
grep -q '^\[camera1\]' "$T/config" || echo "--print-config printed no [camera1]" >> "$T/fail"
result "stillheart.ini.5 documents every key of stillheart run --print-config"

echo "[==========] $((passed + failed)) test(s) run."
echo "[  PASSED  ] $passed test(s)."
if [ "$failed" -gt 0 ]; then echo "[  FAILED  ] $failed test(s)."; exit 1; fi
