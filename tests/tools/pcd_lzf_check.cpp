// pcd_lzf_check — test: the incremental LZF decoder against PCL's LZF codec.
//
//   pcd_lzf_check [ROUNDS]
//
// 1. Seeded buffers of many shapes (random bytes, runs, repeated patterns,
//    columns of floats as in PCD files) are compressed with pcl::lzfCompress
//    and decoded by gdt_lzf_decode, fed and drained in random piece sizes
//    (down to one byte): the output must equal the input, the stream must end
//    on an item boundary, and the sizes must respect the bounds pcd.c relies on.
// 2. Corrupted streams (flipped bytes, truncations, garbage): the decoder must
//    agree with pcl::lzfDecompress on success or failure, and on the bytes
//    when both succeed.  Under ASan this also proves it stays in bounds.
// Exit 0 when everything agrees, 1 with a message on the first difference.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

#include <pcl/io/lzf.h>

#include "private/pcd_lzf.h"

namespace
{

using Bytes = std::vector<std::uint8_t>;

Bytes make_input(std::mt19937_64 &rng, int shape, std::size_t n)
{
    Bytes b(n);
    std::uniform_int_distribution<int> byte(0, 255);
    switch (shape) {
    case 0: // incompressible
        for (auto &v : b)
            v = static_cast<std::uint8_t>(byte(rng));
        break;
    case 1: // long runs
        for (std::size_t i = 0; i < n;) {
            const std::size_t run = 1 + rng() % 600;
            const auto v = static_cast<std::uint8_t>(byte(rng));
            for (std::size_t k = 0; k < run && i < n; k++)
                b[i++] = v;
        }
        break;
    case 2: { // repeated pattern with far references (up to the window)
        const std::size_t period = 1 + rng() % 9000;
        Bytes pat(period);
        for (auto &v : pat)
            v = static_cast<std::uint8_t>(byte(rng));
        for (std::size_t i = 0; i < n; i++)
            b[i] = (rng() % 97 == 0) ? static_cast<std::uint8_t>(byte(rng)) : pat[i % period];
        break;
    }
    default: { // a float column then a double column, like PCD binary_compressed
        std::uniform_real_distribution<double> u(0.0, 1.0);
        const std::size_t nf = n / 12;
        for (std::size_t i = 0; i < nf; i++) {
            const float f = static_cast<float>(500.0 + 100.0 * u(rng));
            std::memcpy(&b[4 * i], &f, 4);
        }
        for (std::size_t i = 0; i < nf; i++) {
            const double d = 480000.0 + std::floor(1000.0 * u(rng)) / 100.0;
            std::memcpy(&b[4 * nf + 8 * i], &d, 8);
        }
        break;
    }
    }
    return b;
}

struct Decoded {
    bool ok;
    Bytes out;
};

// Streams `in` through the decoder in random pieces; success means no bad
// reference, every input byte used, and an item boundary at the end.
Decoded decode_pieces(const Bytes &in, std::size_t out_cap, std::mt19937_64 &rng,
                      std::size_t max_piece)
{
    gdt_lzf_dec dec;
    gdt_lzf_init(&dec);
    Decoded r{false, Bytes(out_cap)};
    std::size_t ip = 0, op = 0;
    for (;;) {
        const std::size_t in_piece = std::min(in.size() - ip, 1 + rng() % max_piece);
        std::size_t out_piece = std::min(out_cap - op, 1 + rng() % max_piece);
        std::size_t used = 0, made = 0;
        const bool discard = rng() % 5 == 0;
        if (discard) // discarded bytes are checked from the window, which keeps the last 8 KiB
            out_piece = std::min<std::size_t>(out_piece, GDT_LZF_WINDOW);
        if (gdt_lzf_decode(&dec, in.data() + ip, in_piece, &used,
                           discard ? nullptr : r.out.data() + op, out_piece, &made) != GDT_LZF_OK) {
            r.out.resize(op + made);
            return r;
        }
        if (discard) {
            for (std::size_t k = 0; k < made; k++)
                r.out[op + k] = dec.window[(dec.produced - made + k) % GDT_LZF_WINDOW];
        }
        ip += used;
        op += made;
        if (used == 0 && made == 0)
            break; // input used up or output full
    }
    r.out.resize(op);
    r.ok = ip == in.size() && gdt_lzf_at_item_boundary(&dec);
    if (op == out_cap && ip < in.size())
        r.ok = false;
    if (dec.produced != op) {
        std::fprintf(stderr, "produced count %llu != %zu\n",
                     static_cast<unsigned long long>(dec.produced), op);
        r.ok = false;
    }
    return r;
}

int fail(const char *what, int round)
{
    std::fprintf(stderr, "pcd_lzf_check: round %d: %s\n", round, what);
    return 1;
}

} // namespace

int main(int argc, char **argv)
{
    const int rounds = argc > 1 ? std::atoi(argv[1]) : 300;
    std::mt19937_64 rng(20240611);
    int compressed_rounds = 0, corrupt_ok = 0, corrupt_bad = 0;
    for (int round = 0; round < rounds; round++) {
        const int shape = round % 4;
        const std::size_t n = 1 + rng() % (round % 10 == 0 ? 200000 : 5000);
        const Bytes input = make_input(rng, shape, n);
        Bytes comp(n + n / 16 + 64);
        const unsigned clen = pcl::lzfCompress(input.data(), static_cast<unsigned>(n), comp.data(),
                                               static_cast<unsigned>(comp.size()));
        if (clen == 0)
            continue; // PCL declines to compress (possible for tiny inputs)
        comp.resize(clen);
        compressed_rounds++;
        if (clen > n + n / 32 + 1 || n > 88ull * clen)
            return fail("compressed size outside the bounds pcd.c checks", round);
        const std::size_t piece = round % 3 == 0 ? 1 : round % 3 == 1 ? 7 : 70000;
        const Decoded d = decode_pieces(comp, n, rng, piece);
        if (!d.ok || d.out != input)
            return fail("valid stream decoded wrongly", round);

        // Corruptions, each compared with PCL's decoder.
        for (int c = 0; c < 8; c++) {
            Bytes bad = comp;
            if (c < 4) {
                for (int k = 0; k <= c; k++)
                    bad[rng() % bad.size()] = static_cast<std::uint8_t>(rng());
            } else if (c < 6) {
                bad.resize(rng() % bad.size());
            } else if (c == 6) {
                for (auto &v : bad)
                    v = static_cast<std::uint8_t>(rng());
            } else {
                bad[0] = static_cast<std::uint8_t>(0xe0 | (rng() & 31)); // reference first
            }
            if (bad.empty())
                continue;
            const std::size_t cap = c % 2 == 0 ? n : n / 2 + 1;
            Bytes ref(cap);
            const unsigned rlen = pcl::lzfDecompress(bad.data(), static_cast<unsigned>(bad.size()),
                                                     ref.data(), static_cast<unsigned>(cap));
            const Decoded mine = decode_pieces(bad, cap, rng, piece);
            const bool pcl_ok = rlen != 0;
            if (pcl_ok != mine.ok) {
                std::fprintf(stderr, "corruption %d: PCL %s (%u bytes), decoder %s (%zu bytes)\n",
                             c, pcl_ok ? "accepts" : "refuses", rlen,
                             mine.ok ? "accepts" : "refuses", mine.out.size());
                return fail("decoder and PCL disagree on a corrupt stream", round);
            }
            if (pcl_ok) {
                ref.resize(rlen);
                if (ref != mine.out)
                    return fail("decoder and PCL decode a corrupt stream differently", round);
                corrupt_ok++;
            } else {
                corrupt_bad++;
            }
        }
    }
    if (compressed_rounds < rounds / 2)
        return fail("too few inputs were compressible", rounds);
    std::printf("pcd_lzf_check: %d streams round-tripped, %d corrupt streams refused, "
                "%d still valid, all as PCL\n",
                compressed_rounds, corrupt_bad, corrupt_ok);
    return 0;
}
