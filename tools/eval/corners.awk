# The ids of the four markers nearest the corners of frame 0's markers in a points file (least
# x+y, x-y, -x+y, -x-y), joined by '|' for a regular expression: the "4 tags (corners of the
# field)" configuration of issue 19, used by landmarks.sh and table2.sh.
#   awk -F, -f tools/eval/corners.awk POINTS.csv
NR > 1 && $1 == 0 { id[++n] = $2; x[n] = $3; y[n] = $4 }
END {
    split("1 1,1 -1,-1 1,-1 -1", s, ",")
    for (k = 1; k <= 4; k++) {
        split(s[k], d, " "); best = ""
        for (i = 1; i <= n; i++) { v = d[1] * x[i] + d[2] * y[i]; if (best == "" || v < best) { best = v; pick = id[i] } }
        printf "%s%s", (k > 1 ? "|" : ""), pick
    }
    print ""
}
