# Sourced by the table scripts of tools/eval (blood.sh, carry.sh, landmarks.sh, landmarks3d.sh,
# table2.sh), which set OUT (their output folder) and HERE (this folder) first.

# num NAME KEY: the first number under "KEY" in the evaluator's JSON $OUT/json/NAME.json (nan and
# inf too, as stillheart-eval prints a measure with nothing to measure).
num() { sed -n "s/.*\"$2\": \([-0-9.eEnaif+]*\).*/\1/p" "$OUT/json/$1.json" | head -1; }

# num_first NAME KEY [OBJECT]: the first number under KEY in OUT/json/NAME.json, inside the object
# OBJECT when given; num takes a line's last, and stillheart-eval --landmark-rows' JSON repeats its
# keys inside its objects (covered, image, reprojected).
num_first() {
    if [ $# -gt 2 ]; then sed -n "s/.*\"$3\": {\([^}]*\)}.*/\1/p" "$OUT/json/$1.json"; else cat "$OUT/json/$1.json"; fi |
        grep -o "\"$2\": [-0-9.eEnaif+]*" | head -1 | sed 's/.*: //'
}

# four_tags POINTS OUT: writes to OUT the header and the rows of POINTS (a points file) of the
# four markers nearest the corners of frame 0's markers (corners.awk: issue 19's "4 tags"), and
# prints their ids joined by '|'.
four_tags() {
    _ids=$(awk -F, -f "$HERE/corners.awk" "$1")
    awk -F, -v ids="$_ids" 'NR == 1 || $2 ~ "^(" ids ")$"' "$1" > "$2"
    echo "$_ids"
}
