// Per-point principal curvatures by CGAL's jet fitting (CGAL::Monge_via_jet_fitting), as a
// benchmark peer for the curvature library. Built and driven by curvature/studies/peers/cgal.py.
//
// Usage: jet_fitting [INPUT [OUTPUT]]   (stdin / stdout when omitted or "-")
//
// Input, little-endian:
//   8 bytes  magic "CGJETIN1"
//   5 int64  n, k, jet degree d, Monge degree d', threads (0 = hardware concurrency)
//   n*3 float64  x y z of every point
// Output:
//   8 bytes  magic "CGJETOU1"
//   1 int64  n
//   n*6 float64  per point: k1 k2 (CGAL's maximal and minimal principal curvature, in CGAL's
//                sign, relative to the Monge normal), nx ny nz (the Monge normal, arbitrary
//                sign), condition number of the least-squares system
//   n int8       status: 0 ok, 1 too few neighbors, 2 degenerate fit (CGAL raised, or the
//                condition number exceeds kMaxCondition or is not finite), 4 non-finite result
//
// Each point is fitted over its k nearest points (itself included) from CGAL's kd-tree. Points are
// split into contiguous blocks, one std::thread each; every point's result depends only on its
// neighborhood, so the output is the same for any thread count.

#include <CGAL/Simple_cartesian.h>
#include <CGAL/Search_traits_3.h>
#include <CGAL/Orthogonal_k_neighbor_search.h>
#include <CGAL/Monge_via_jet_fitting.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Traits = CGAL::Search_traits_3<Kernel>;
using Knn = CGAL::Orthogonal_k_neighbor_search<Traits>;
using Tree = Knn::Tree;
using Fitting = CGAL::Monge_via_jet_fitting<Kernel>;

constexpr char kMagicIn[] = "CGJETIN1";
constexpr char kMagicOut[] = "CGJETOU1";
constexpr int kFields = 6;
// CGAL preconditions the system, so sound fits stay below about 1e4 (degree 4, plane-like
// neighborhoods); collinear or coincident neighbors give infinity and a meaningless jet.
constexpr double kMaxCondition = 1e10;

enum Status : int8_t { kOk = 0, kTooFew = 1, kDegenerate = 2, kNonFinite = 4 };

struct Params {
    int64_t n, k, degree, monge_degree, threads;
};

void read_exact(std::FILE* f, void* dst, size_t bytes, const char* what) {
    if (std::fread(dst, 1, bytes, f) != bytes) {
        throw std::runtime_error(std::string("input ended while reading ") + what);
    }
}

void write_exact(std::FILE* f, const void* src, size_t bytes) {
    if (std::fwrite(src, 1, bytes, f) != bytes) {
        throw std::runtime_error("could not write the output");
    }
}

Params read_params(std::FILE* f) {
    char magic[8];
    read_exact(f, magic, sizeof magic, "the magic");
    if (std::memcmp(magic, kMagicIn, sizeof magic) != 0) {
        throw std::runtime_error("input does not start with the magic CGJETIN1");
    }
    int64_t h[5];
    read_exact(f, h, sizeof h, "the header");
    Params p{h[0], h[1], h[2], h[3], h[4]};
    if (p.n < 1) throw std::runtime_error("n must be positive");
    if (p.k < 1) throw std::runtime_error("k must be positive");
    if (p.degree < 1 || p.degree > 4) throw std::runtime_error("jet degree must be 1..4");
    if (p.monge_degree < 1 || p.monge_degree > p.degree) {
        throw std::runtime_error("Monge degree must be 1..jet degree");
    }
    return p;
}

// Fits points [begin, end) of `pts`; writes kFields values and one status per point.
void fit_block(const Tree& tree, const std::vector<Point>& pts, const Params& p, size_t begin,
               size_t end, double* values, int8_t* status) {
    const size_t k = static_cast<size_t>(std::min<int64_t>(p.k, p.n));
    // The least-squares system needs at least as many points as jet coefficients.
    const size_t needed = static_cast<size_t>((p.degree + 1) * (p.degree + 2) / 2);
    std::vector<Point> nbrs;
    nbrs.reserve(k);
    for (size_t i = begin; i < end; ++i) {
        double* out = values + kFields * i;
        std::fill(out, out + kFields, std::nan(""));
        if (k < needed) {
            status[i] = kTooFew;
            continue;
        }
        nbrs.clear();
        Knn search(tree, pts[i], static_cast<unsigned int>(k));
        for (const auto& hit : search) nbrs.push_back(hit.first);
        try {
            Fitting fitting;
            Fitting::Monge_form form = fitting(nbrs.begin(), nbrs.end(),
                                               static_cast<size_t>(p.degree),
                                               static_cast<size_t>(p.monge_degree));
            const Kernel::Vector_3 nrm = form.normal_direction();
            out[0] = form.principal_curvatures(0);
            out[1] = form.principal_curvatures(1);
            out[2] = nrm.x();
            out[3] = nrm.y();
            out[4] = nrm.z();
            out[5] = fitting.condition_number();
            bool finite = true;
            for (int j = 0; j < kFields - 1; ++j) finite = finite && std::isfinite(out[j]);
            if (!(out[5] <= kMaxCondition)) {  // also catches a NaN condition number
                status[i] = kDegenerate;
            } else {
                status[i] = finite ? kOk : kNonFinite;
            }
        } catch (const std::exception&) {
            status[i] = kDegenerate;  // a CGAL precondition or assertion failed on this point
        }
    }
}

std::FILE* open_or(const char* path, const char* mode, std::FILE* fallback) {
    if (path == nullptr || std::strcmp(path, "-") == 0) return fallback;
    std::FILE* f = std::fopen(path, mode);
    if (f == nullptr) throw std::runtime_error(std::string("cannot open ") + path);
    return f;
}

void run(const char* in_path, const char* out_path) {
    std::FILE* in = open_or(in_path, "rb", stdin);
    const Params p = read_params(in);
    std::vector<double> xyz(static_cast<size_t>(p.n) * 3);
    read_exact(in, xyz.data(), xyz.size() * sizeof(double), "the points");
    if (in != stdin) std::fclose(in);

    std::vector<Point> pts;
    pts.reserve(static_cast<size_t>(p.n));
    for (int64_t i = 0; i < p.n; ++i) {
        pts.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    }
    Tree tree(pts.begin(), pts.end());
    tree.build();  // built before the threads start: concurrent queries then only read it

    const size_t n = static_cast<size_t>(p.n);
    std::vector<double> values(n * kFields);
    std::vector<int8_t> status(n);
    size_t threads = p.threads > 0 ? static_cast<size_t>(p.threads)
                                   : std::max(1u, std::thread::hardware_concurrency());
    threads = std::min(threads, n);
    std::vector<std::thread> pool;
    std::vector<std::exception_ptr> errors(threads);
    for (size_t t = 0; t < threads; ++t) {
        const size_t begin = n * t / threads, end = n * (t + 1) / threads;
        pool.emplace_back([&, t, begin, end] {
            try {
                fit_block(tree, pts, p, begin, end, values.data(), status.data());
            } catch (...) {
                errors[t] = std::current_exception();
            }
        });
    }
    for (auto& th : pool) th.join();
    for (auto& e : errors) {
        if (e) std::rethrow_exception(e);
    }

    std::FILE* out = open_or(out_path, "wb", stdout);
    write_exact(out, kMagicOut, 8);
    write_exact(out, &p.n, sizeof p.n);
    write_exact(out, values.data(), values.size() * sizeof(double));
    write_exact(out, status.data(), status.size());
    if (std::fflush(out) != 0) throw std::runtime_error("could not write the output");
    if (out != stdout) std::fclose(out);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc > 3) {
        std::fprintf(stderr, "usage: %s [INPUT [OUTPUT]]\n", argv[0]);
        return 2;
    }
    try {
        run(argc > 1 ? argv[1] : nullptr, argc > 2 ? argv[2] : nullptr);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "jet_fitting: %s\n", e.what());
        return 1;
    }
    return 0;
}
