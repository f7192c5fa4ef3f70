/* Point filters (io/gdt_filter.h): class-list parsing, the canonical
 * description and its round trip, the test order of the drop reasons. */
#include <stdio.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_filter.h"

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK(&checks, cond, __VA_ARGS__)

static uint64_t rng_state = UINT64_C(0x9e3779b97f4a7c15);

static int parse(gdt_point_filter *f, int mode, const char *s, int *code)
{
    gdt_error e;
    gdt_error_clear(&e);
    gdt_status st = gdt_filter_parse_classes(f, mode, "--keep-class", s, &e);
    *code = e.code;
    return st == GDT_OK;
}

static void test_class_lists(void)
{
    static const struct { const char *s; int code; const char *canon; } cases[] = {
        {"2", 0, "2"},           {"2,9", 0, "2,9"},         {"3-5", 0, "3-5"},
        {"5,3-4,17", 0, "3-5,17"}, {"0-255", 0, "0-255"},   {"7,7,7", 0, "7"},
        {"1,2", 0, "1,2"},       {"255", 0, "255"},         {"007", 0, "7"},
        {"", 2301, NULL},        {",", 2301, NULL},         {"2,", 2301, NULL},
        {",2", 2301, NULL},      {"2,,3", 2301, NULL},      {"-2", 2301, NULL},
        {"2-", 2301, NULL},      {"5-3", 2301, NULL},       {"2 ", 2301, NULL},
        {" 2", 2301, NULL},      {"2.0", 2301, NULL},       {"+2", 2301, NULL},
        {"x", 2301, NULL},       {"1-2-3", 2301, NULL},     {"256", 2302, NULL},
        {"2,300", 2302, NULL},   {"1-256", 2302, NULL},
        {"99999999999999999999", 2302, NULL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        gdt_point_filter f;
        char list[1024];
        int code = 0;
        memset(&f, 0, sizeof f);
        int ok = parse(&f, 1, cases[i].s, &code);
        CHECK(ok == (cases[i].code == 0) && (ok || code == cases[i].code),
              "'%s': ok %d code %d, want %d", cases[i].s, ok, code, cases[i].code);
        if (!ok) {
            CHECK(f.class_mode == 0, "'%s': a failed parse changed the filter", cases[i].s);
            continue;
        }
        gdt_filter_class_list(&f, list, sizeof list);
        CHECK(strcmp(list, cases[i].canon) == 0, "'%s' -> '%s', want '%s'", cases[i].s, list,
              cases[i].canon);
    }
    {
        gdt_point_filter f;
        int code = 0;
        memset(&f, 0, sizeof f);
        CHECK(parse(&f, 1, "2", &code) && parse(&f, 1, "9", &code) && f.classes[2] &&
                  f.classes[9] && f.class_mode == 1,
              "repeated --keep-class lists add up");
        CHECK(!parse(&f, -1, "7", &code) && code == 2303 && !f.classes[7],
              "--drop-class after --keep-class: code %d", code);
    }
}

/* Random class sets, returns and withheld: describe, parse back, same. */
static void test_description_round_trip(void)
{
    for (int n = 0; n < 2000; n++) {
        gdt_point_filter f, g;
        char d[1200], d2[1200];
        uint64_t r = gdt_splitmix64(&rng_state);
        memset(&f, 0, sizeof f);
        f.class_mode = (int)(r % 3) - 1;
        f.returns = (gdt_returns)((r >> 2) % 4);
        f.keep_withheld = (int)((r >> 4) & 1);
        for (unsigned c = 0; f.class_mode != 0 && c < 256; c++) {
            unsigned density = (unsigned)((r >> 5) % 4); /* sparse to dense sets */
            f.classes[c] = (gdt_splitmix64(&rng_state) % 4) < density;
        }
        gdt_filter_describe(&f, d, sizeof d);
        memset(&g, 0xff, sizeof g);
        CHECK(gdt_filter_from_description(&g, d) == 0, "'%s' does not parse back", d);
        gdt_filter_describe(&g, d2, sizeof d2);
        CHECK(strcmp(d, d2) == 0 && g.class_mode == f.class_mode && g.returns == f.returns &&
                  g.keep_withheld == f.keep_withheld &&
                  (f.class_mode == 0 || memcmp(f.classes, g.classes, 256) == 0),
              "'%s' came back as '%s'", d, d2);
    }
    {
        static const char *const bad[] = {
            "", "classes all", "classes 2 returns all withheld drop",
            "keep-class 3,2 returns all withheld drop", /* not canonical */
            "keep-class 2 returns some withheld drop", "keep-class 2 returns all withheld no",
            "keep-class x returns all withheld drop", "take-class 2 returns all withheld drop",
            "classes all returns all withheld drop extra"};
        for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
            gdt_point_filter g;
            CHECK(gdt_filter_from_description(&g, bad[i]) != 0, "'%s' accepted", bad[i]);
        }
    }
    {
        gdt_point_filter f;
        char d[1200];
        memset(&f, 0, sizeof f);
        gdt_filter_describe(&f, d, sizeof d);
        CHECK(strcmp(d, "classes all returns all withheld drop") == 0 &&
                  gdt_filter_is_default(&f),
              "default: '%s'", d);
    }
}

static gdt_src_point pt(unsigned cls, unsigned ret, unsigned nret, unsigned flags)
{
    gdt_src_point p;
    memset(&p, 0, sizeof p);
    p.cls = (uint8_t)cls;
    p.ret = (uint8_t)ret;
    p.nret = (uint8_t)nret;
    p.flags = (uint8_t)flags;
    return p;
}

static void test_reasons(void)
{
    gdt_point_filter f;
    gdt_src_point p;
    int code = 0;
    memset(&f, 0, sizeof f);
    p = pt(2, 1, 1, GDT_PT_WITHHELD);
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_WITHHELD, "withheld dropped by default");
    f.keep_withheld = 1;
    CHECK(gdt_filter_test(&f, &p) == GDT_KEEP, "--keep-withheld keeps it");
    f.keep_withheld = 0;
    CHECK(parse(&f, 1, "2", &code), "parse");
    f.returns = GDT_RETURNS_LAST;
    p = pt(3, 1, 2, GDT_PT_WITHHELD);
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_WITHHELD, "withheld first");
    p = pt(3, 1, 2, GDT_PT_SYNTHETIC | GDT_PT_OVERLAP);
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_CLASS, "class before return");
    p = pt(2, 1, 2, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_RETURN, "return 1 of 2 is not the last");
    p = pt(2, 2, 2, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_KEEP, "return 2 of 2 is the last");
    f.returns = GDT_RETURNS_FIRST;
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_RETURN, "return 2 is not the first");
    p = pt(2, 1, 3, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_KEEP, "return 1 is the first");
    f.returns = GDT_RETURNS_SINGLE;
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_RETURN, "3 returns are not single");
    p = pt(2, 1, 1, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_KEEP, "single return");
    memset(&f, 0, sizeof f);
    CHECK(parse(&f, -1, "7,18", &code), "parse");
    p = pt(18, 1, 1, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_DROP_CLASS, "--drop-class drops 18");
    p = pt(200, 1, 1, 0);
    CHECK(gdt_filter_test(&f, &p) == GDT_KEEP, "--drop-class keeps 200");
    CHECK(gdt_filter_need(&f) == (GDT_SRC_NEED_XYZ | GDT_SRC_NEED_CLASS | GDT_SRC_NEED_FLAGS),
          "class filter and withheld test need class and flags");
    f.keep_withheld = 1;
    CHECK(gdt_filter_need(&f) == (GDT_SRC_NEED_XYZ | GDT_SRC_NEED_CLASS), "class only");
    memset(&f, 0, sizeof f);
    f.keep_withheld = 1;
    CHECK(gdt_filter_need(&f) == GDT_SRC_NEED_XYZ && !gdt_filter_uses_attributes(&f),
          "nothing to test: coordinates only");
}

int main(void)
{
    test_class_lists();
    test_description_round_trip();
    test_reasons();
    return gdt_check_finish(&checks, "test_filter");
}
