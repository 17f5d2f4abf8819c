// stillheart-calib's inputs: one camera's frames, from a Y4M video or a folder of images, as
// grey (luma) planes. Frames of different cameras taken at the same time share an index.
#ifndef STILLHEART_CALIB_INPUT_H
#define STILLHEART_CALIB_INPUT_H

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

class calib_input {
public:
    virtual ~calib_input() = default;
    // The next frame's luma (CV_8UC1, owned by the caller); false at the end. Throws
    // std::runtime_error naming the file on a read error.
    virtual bool next(cv::Mat &grey) = 0;
    // Frames this input holds; -1 when only reading tells (a video).
    virtual int count() const = 0;
    const std::string &name() const { return name_; }

protected:
    std::string name_;
};

// A folder (PNG or JPEG files, taken in name order) or else a Y4M file. Throws std::runtime_error.
std::unique_ptr<calib_input> calib_input_open(const std::string &path);

#endif
