// pcl_normals — the comparison point for splatd's prep: PCL's NormalEstimationOMP on a PLY.
//
//   pcl_normals FILE.ply [k = 24] [threads = 2] [runs = 3]
//
// Reads a binary little-endian PLY (vertex x y z as float or double, any other properties),
// then times NormalEstimationOMP (kd-tree build + k-nearest-neighbour search + PCA normals)
// and prints "pcl_normals_s <median seconds> points <n>". Built and run by bench_prep.sh only
// when PCL's headers are installed; never part of the build.
#include <pcl/features/normal_3d_omp.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

static int type_size(const std::string &t)
{
    if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
    if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
    if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
    if (t == "double" || t == "float64") return 8;
    return -1;
}

static bool read_ply(const char *path, pcl::PointCloud<pcl::PointXYZ> &out)
{
    std::ifstream f(path, std::ios::binary);
    if (!f) return false;
    std::string line;
    long n = -1;
    int stride = 0, off[3] = {-1, -1, -1}, dbl[3] = {0, 0, 0};
    bool in_vertex = false, le = false;
    while (std::getline(f, line)) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        std::istringstream ss(line);
        std::string w;
        ss >> w;
        if (w == "format") { std::string fmt; ss >> fmt; le = fmt == "binary_little_endian"; }
        else if (w == "element") { std::string name; ss >> name; in_vertex = name == "vertex"; if (in_vertex) ss >> n; }
        else if (w == "property" && in_vertex) {
            std::string t, name;
            ss >> t >> name;
            int s = type_size(t);
            if (s < 0) return false; // list properties in vertex: unsupported here
            int axis = name == "x" ? 0 : name == "y" ? 1 : name == "z" ? 2 : -1;
            if (axis >= 0) { off[axis] = stride; dbl[axis] = s == 8; }
            stride += s;
        } else if (w == "end_header") break;
    }
    if (!le || n <= 0 || off[0] < 0 || off[1] < 0 || off[2] < 0) return false;
    std::vector<char> buf((size_t)n * stride);
    if (!f.read(buf.data(), (std::streamsize)buf.size())) return false;
    out.resize((size_t)n);
    for (long i = 0; i < n; i++) {
        const char *r = buf.data() + (size_t)i * stride;
        float v[3];
        for (int a = 0; a < 3; a++) {
            if (dbl[a]) { double d; std::memcpy(&d, r + off[a], 8); v[a] = (float)d; }
            else std::memcpy(&v[a], r + off[a], 4);
        }
        out[(size_t)i] = pcl::PointXYZ(v[0], v[1], v[2]);
    }
    return true;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        std::fprintf(stderr, "usage: pcl_normals FILE.ply [k] [threads] [runs]\n");
        return 2;
    }
    int k = argc > 2 ? std::atoi(argv[2]) : 24, threads = argc > 3 ? std::atoi(argv[3]) : 2;
    int runs = argc > 4 ? std::atoi(argv[4]) : 3;
    pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
    if (!read_ply(argv[1], *cloud)) {
        std::fprintf(stderr, "pcl_normals: cannot read %s (binary little-endian PLY with x y z)\n", argv[1]);
        return 1;
    }
    std::vector<double> t;
    for (int r = 0; r < runs; r++) {
        pcl::PointCloud<pcl::Normal> normals;
        pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
        pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(threads);
        auto t0 = std::chrono::steady_clock::now();
        ne.setInputCloud(cloud);
        ne.setSearchMethod(tree);
        ne.setKSearch(k);
        ne.compute(normals);
        t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(t.begin(), t.end());
    std::printf("pcl_normals_s %.3f points %zu\n", t[t.size() / 2], cloud->size());
    return 0;
}
