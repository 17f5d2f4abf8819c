// Frames for stillheart-calib through libstillheart's own readers (Y4M, PNG / JPEG), so the tool
// reads exactly what the rest of stillheart reads and needs no OpenCV codec module.
#include "input.h"

#include <dirent.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <stdexcept>

extern "C" {
#include "stillheart/imageio.h"
#include "stillheart/y4m.h"
}

namespace {

std::string lower(std::string s)
{
    for (auto &c : s) c = (char)std::tolower((unsigned char)c);
    return s;
}

cv::Mat luma_copy(const sh_image &img)
{
    const sh_plane &p = img.plane[0];
    cv::Mat wrap(p.height, p.width, CV_8UC1, p.data, (size_t)p.stride);
    return wrap.clone();
}

class y4m_input : public calib_input {
public:
    explicit y4m_input(const std::string &path)
    {
        name_ = path;
        if (sh_y4m_reader_open(path.c_str(), &reader_) != SH_OK) throw std::runtime_error(sh_error_message());
        const sh_y4m_header *h = sh_y4m_reader_header(reader_);
        if (sh_image_create(&img_, h->format, h->width, h->height) != SH_OK) {
            sh_y4m_reader_close(reader_);
            throw std::runtime_error(sh_error_message());
        }
    }
    ~y4m_input() override
    {
        sh_image_destroy(&img_);
        sh_y4m_reader_close(reader_);
    }
    bool next(cv::Mat &grey) override
    {
        sh_status st = sh_y4m_reader_read(reader_, &img_);
        if (st == SH_EEOF) return false;
        if (st != SH_OK) throw std::runtime_error(sh_error_message());
        grey = luma_copy(img_); // Y of every Y4M colour space is the first plane
        return true;
    }
    int count() const override { return -1; }

private:
    sh_y4m_reader *reader_ = nullptr;
    sh_image img_{};
};

class folder_input : public calib_input {
public:
    explicit folder_input(const std::string &path)
    {
        name_ = path;
        DIR *d = opendir(path.c_str());
        if (!d) throw std::runtime_error(path + ": cannot open the folder: " + std::strerror(errno));
        while (dirent *e = readdir(d)) {
            std::string n = e->d_name, l = lower(n);
            auto ends = [&](const char *x) {
                size_t k = std::strlen(x);
                return l.size() > k && l.compare(l.size() - k, k, x) == 0;
            };
            if (ends(".png") || ends(".jpg") || ends(".jpeg")) files_.push_back(path + "/" + n);
        }
        closedir(d);
        std::sort(files_.begin(), files_.end());
        if (files_.empty()) throw std::runtime_error(path + ": no .png, .jpg or .jpeg files in the folder");
    }
    bool next(cv::Mat &grey) override
    {
        if (pos_ >= files_.size()) return false;
        sh_image img{};
        if (sh_imageio_read_gray(files_[pos_].c_str(), &img) != SH_OK) throw std::runtime_error(sh_error_message());
        grey = luma_copy(img);
        sh_image_destroy(&img);
        pos_++;
        return true;
    }
    int count() const override { return (int)files_.size(); }

private:
    std::vector<std::string> files_;
    size_t pos_ = 0;
};

} // namespace

std::unique_ptr<calib_input> calib_input_open(const std::string &path)
{
    struct stat st;
    if (stat(path.c_str(), &st) != 0) throw std::runtime_error(path + ": " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) return std::unique_ptr<calib_input>(new folder_input(path));
    return std::unique_ptr<calib_input>(new y4m_input(path));
}
