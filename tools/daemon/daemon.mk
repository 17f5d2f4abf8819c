# The daemon (stillheart run): config (inih), sd_notify, run demo, daemon tests and bench.
ifeq ($(call have,inih),1)
CFLAGS_ALL += -DSH_HAVE_INIH $(shell $(PKG_CONFIG) --cflags inih)
LDLIBS_ALL += $(shell $(PKG_CONFIG) --libs inih)
endif
