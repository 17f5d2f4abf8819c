# The manual pages (man/, troff): `make man` fills in the version (include/stillheart/cli.h) and writes them
# to $(BUILD)/man; make install and the Debian packages install them; test_man checks them
# against the programs' --help and renders them (issue 18).
MAN_SRC := $(wildcard man/*.[1-8])
MAN_OUT := $(MAN_SRC:man/%=$(BUILD)/man/%)
SH_VERSION := $(shell sed -n 's/^\#define SH_VERSION "\(.*\)"/\1/p' include/stillheart/cli.h)
.PHONY: man install-man
man: $(MAN_OUT)
all: man
$(BUILD)/man/%: man/% include/stillheart/cli.h
	@mkdir -p $(dir $@)
	sed 's/@VERSION@/$(SH_VERSION)/g' $< > $@

# Pages of the tools installed only where the tool is built (stillheart-calib needs OpenCV).
MAN_TOOL_PAGES = $(foreach p,$(USER_TOOLS),$(if $(filter $(BUILD)/$(p),$(TOOLS)),,$(BUILD)/man/$(p).1))
install: install-man
install-man: man
	install -d $(DESTDIR)$(PREFIX)/share/man/man1 $(DESTDIR)$(PREFIX)/share/man/man5
	install -m 0644 $(filter-out $(MAN_TOOL_PAGES),$(filter %.1,$(MAN_OUT))) $(DESTDIR)$(PREFIX)/share/man/man1/
	install -m 0644 $(filter %.5,$(MAN_OUT)) $(DESTDIR)$(PREFIX)/share/man/man5/

$(BUILD)/tests/test_man: tools/man/test_man.sh $(MAN_OUT) $(APP)
	@mkdir -p $(dir $@)
	cp $< $@
	chmod +x $@
TOOL_TESTS += $(BUILD)/tests/test_man
