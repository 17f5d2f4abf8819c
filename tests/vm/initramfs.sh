# Sourced by tests/vm/run.sh and tests/vm/show.sh: the pieces of a guest's busybox initramfs
# that both make.

# vm_modules ROOT KDIR KVER MODULE: MODULE and the modules it depends on, from the kernel tree
# KDIR, decompressed (busybox insmod takes no .xz) into ROOT/mods as 01-NAME.ko, 02-... in the
# order they must be loaded.
vm_modules() {
    n=0
    for m in $(/sbin/modprobe -d "$2" -S "$3" --show-depends "$4" | awk '$1 == "insmod" {print $2}'); do
        n=$((n + 1))
        case "$m" in
            *.xz) xz -dc "$m" > "$1/mods/$(printf %02d $n)-$(basename "${m%.xz}")" ;;
            *) cp "$m" "$1/mods/$(printf %02d $n)-$(basename "$m")" ;;
        esac
    done
    [ "$n" -gt 0 ]
}

# vm_libs ROOT PROGRAM...: the shared libraries the programs need (ldd), and ld.so under its
# /lib64 name, which a program may ask for.
vm_libs() {
    r=$1; shift
    for lib in $(ldd "$@" 2>/dev/null | awk '/=>/ {print $3} /^\t\// {print $1}' | sort -u); do
        mkdir -p "$r$(dirname "$lib")"; cp -L "$lib" "$r$lib"
    done
    mkdir -p "$r/lib64"; [ -e "$r/lib64/ld-linux-x86-64.so.2" ] || cp -L /lib64/ld-linux-x86-64.so.2 "$r/lib64/"
}
