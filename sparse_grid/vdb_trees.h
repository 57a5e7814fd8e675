#pragma once
// OpenVDB, with the trees and grids this project stores compiled once, in vdb_trees.cpp.
//
// A translation unit that names openvdb::Grid<T> or openvdb::tree::Tree<T> emits their virtual
// tables, and with them every virtual member (I/O, printing, clipping, voxel counting with its TBB
// reductions): about 0.5 MB of code and a third of the compile time of a solver test. The
// explicit instantiation declarations below keep those members out of every file but one
// (docs/design.md §2). Every project file includes OpenVDB through this header
// (tests/check_layering.py), so that no file instantiates these trees before the declarations.
#include <openvdb/openvdb.h>

// Int32: the leaf-order slot numbering (BlockLayout); Mask: active blocks and liquid topology;
// Float: level sets and volume fields.
extern template class openvdb::tree::Tree<openvdb::Int32Tree::RootNodeType>;
extern template class openvdb::tree::Tree<openvdb::MaskTree::RootNodeType>;
extern template class openvdb::tree::Tree<openvdb::FloatTree::RootNodeType>;
extern template class openvdb::Grid<openvdb::Int32Tree>;
extern template class openvdb::Grid<openvdb::MaskTree>;
extern template class openvdb::Grid<openvdb::FloatTree>;
