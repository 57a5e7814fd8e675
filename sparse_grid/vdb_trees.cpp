// The one instantiation of the OpenVDB trees and grids declared in vdb_trees.h.
#include "sparse_grid/vdb_trees.h"

template class openvdb::tree::Tree<openvdb::Int32Tree::RootNodeType>;
template class openvdb::tree::Tree<openvdb::MaskTree::RootNodeType>;
template class openvdb::tree::Tree<openvdb::FloatTree::RootNodeType>;
template class openvdb::Grid<openvdb::Int32Tree>;
template class openvdb::Grid<openvdb::MaskTree>;
template class openvdb::Grid<openvdb::FloatTree>;
