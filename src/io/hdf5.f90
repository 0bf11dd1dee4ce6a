!> Thin wrapper over HDF5's Fortran API: create/open files, groups, datasets and attributes of
!> float64, int32 and strings, with object timestamps switched off (so that two runs with the same
!> input give files with equal content). Errors name `file::object`.
!>
!> Usage:
!>     call h5_create(file, "model.h5.tmp", error)
!>     call h5_write(file, "/box/length", [20.0_wp, 20.0_wp, 20.0_wp], error)
!>     call h5_close(file, error)
module anm_io_hdf5
   use hdf5, only: hid_t, hsize_t, size_t, h5open_f, h5fcreate_f, h5fopen_f, h5fclose_f, h5gcreate_f, h5gclose_f, &
      & h5screate_simple_f, h5screate_f, h5sclose_f, h5dcreate_f, h5dopen_f, h5dwrite_f, h5dread_f, h5dclose_f, &
      & h5dget_space_f, h5sget_simple_extent_ndims_f, h5sget_simple_extent_dims_f, h5pcreate_f, h5pclose_f, &
      & h5pset_obj_track_times_f, h5acreate_f, h5awrite_f, h5aread_f, h5aclose_f, h5aopen_f, h5tcopy_f, &
      & h5tset_size_f, h5tclose_f, h5dget_type_f, h5tget_size_f, h5lexists_f, h5aexists_f, &
      & H5F_ACC_TRUNC_F, H5F_ACC_RDONLY_F, H5P_DATASET_CREATE_F, H5P_GROUP_CREATE_F, H5S_SCALAR_F, &
      & H5T_NATIVE_DOUBLE, H5T_NATIVE_INTEGER, H5T_FORTRAN_S1, h5eset_auto_f
   use, intrinsic :: iso_c_binding, only: c_ptr, c_char, c_null_char, c_null_ptr, c_loc, c_f_pointer, c_associated, &
      & c_size_t
   use anm_core_kinds, only: wp, i8
   use anm_core_output, only: file_size
   use anm_core_error, only: error_type, fatal_error, error_code
   implicit none
   private

   public :: h5_file_type, h5_create, h5_open_read, h5_close, h5_group, h5_write, h5_write_attr, h5_read, &
      & h5_read_attr, h5_dims, h5_exists, h5_read_strings, h5_parallel_type, block_start

   !> The processes that write one file together (parallel HDF5, MPI-IO): the MPI build extends it
   !> (mpi/src/output.f90); the serial program uses none. Every process makes the same calls with
   !> the same arguments (metadata, attributes); the data of a dataset is written by process 0
   !> alone, or, for datasets written with `split`, each process writing a contiguous block of the
   !> last dimension (a hyperslab), collectively.
   type, abstract :: h5_parallel_type
      !> This process and the number of processes.
      integer :: rank = 0, nranks = 1
   contains
      !> New file-access (MPI-IO driver) and transfer (collective) property lists.
      procedure(parallel_lists), deferred :: property_lists
      !> The text of process 0 on every process (collective).
      procedure(parallel_share), deferred :: share
      !> Wait for every process (collective).
      procedure(parallel_barrier), deferred :: barrier
   end type h5_parallel_type

   abstract interface
      subroutine parallel_lists(self, fapl, dxpl)
         import :: h5_parallel_type, hid_t
         !> Processes.
         class(h5_parallel_type), intent(in) :: self
         !> File-access and data-transfer property lists (the caller closes them).
         integer(hid_t), intent(out) :: fapl, dxpl
      end subroutine parallel_lists

      subroutine parallel_share(self, text)
         import :: h5_parallel_type
         !> Processes.
         class(h5_parallel_type), intent(in) :: self
         !> Process 0's text on entry there; on return, the same on every process.
         character(len=:), allocatable, intent(inout) :: text
      end subroutine parallel_share

      subroutine parallel_barrier(self)
         import :: h5_parallel_type
         !> Processes.
         class(h5_parallel_type), intent(in) :: self
      end subroutine parallel_barrier
   end interface

   !> An open HDF5 file.
   type :: h5_file_type
      !> File name (for messages).
      character(len=:), allocatable :: name
      !> HDF5 identifier.
      integer(hid_t) :: id = -1
      !> Dataset and group creation property lists (timestamps off).
      integer(hid_t) :: dcpl = -1, gcpl = -1
      !> Built in memory (HDF5's core driver) and written to `name` by h5_close.
      logical :: in_memory = .false.
      !> Written by several processes together (h5_parallel_type): this process, their number and
      !> the collective transfer property list.
      logical :: parallel = .false.
      integer :: rank = 0, nranks = 1
      integer(hid_t) :: dxpl = -1
   end type h5_file_type

   !> A dataset being written: its handles, the memory and file dataspaces and the transfer list of
   !> this process' part, and the status so far (`start_write`, `end_write`).
   type :: dataset_write_type
      integer(hid_t) :: dset = -1, space = -1, mspace = -1, fspace = -1, xfer = -1
      integer :: st = 0
   end type dataset_write_type

   !> A string read from a file.
   type :: h5_text_type
      character(len=:), allocatable :: s
   end type h5_text_type

   interface
      function c_strlen(p) bind(c, name="strlen") result(n)
         import :: c_ptr, c_size_t
         type(c_ptr), value, intent(in) :: p
         integer(c_size_t) :: n
      end function c_strlen
   end interface

   !> Write a dataset (float64 or int32 arrays of rank 1-3, or a string). In a file written in
   !> parallel (h5_create with `par`), `split = .true.` makes each process write its block of the
   !> last dimension (every process passes the whole array); without it process 0 writes it all.
   !> With `split`, `offset` >= 0 and `total` (parallel files only), each process passes only the
   !> entries it writes, offset+1..offset+size of the last dimension of a dataset of `total`
   !> there (`offset` < 0: as without it).
   interface h5_write
      module procedure :: write_real1, write_real2, write_real3, write_int1, write_string, write_strings
   end interface h5_write

   !> Write an attribute of a group or dataset.
   interface h5_write_attr
      module procedure :: attr_int, attr_int64, attr_real, attr_string
   end interface h5_write_attr

   !> Read a dataset.
   interface h5_read
      module procedure :: read_real1, read_real2, read_real3, read_int1, read_string
   end interface h5_read

   !> Read an attribute.
   interface h5_read_attr
      module procedure :: read_attr_int, read_attr_real, read_attr_string
   end interface h5_read_attr

contains

   subroutine fail(error, file, obj, what)
      type(error_type), allocatable, intent(out) :: error
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: obj, what
      call fatal_error(error, file%name//"::"//obj//": "//what, error_code%io)
   end subroutine fail

   !> Create a file for writing. It is built in memory (HDF5's core driver, no backing store) and
   !> written to disk by h5_close with checked writes: a full disk or a file-size limit is then an
   !> error of h5_close, and HDF5 never holds a half-written file (which it would try to flush
   !> again, and crash, at program exit).
   !>
   !> With `par` (the MPI build), every process of `par` creates the same file collectively through
   !> MPI-IO, written directly (no memory image); h5_close is then collective too.
   subroutine h5_create(file, name, error, par)
      use hdf5, only: h5pset_fapl_core_f, H5P_FILE_ACCESS_F, H5P_DEFAULT_F
      !> Handle.
      type(h5_file_type), intent(out) :: file
      !> File name.
      character(len=*), intent(in) :: name
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      !> Processes writing the file together (collective create).
      class(h5_parallel_type), intent(in), optional :: par
      integer :: st, s2
      integer(hid_t) :: fapl
      file%name = name
      call h5open_f(st)
      call h5eset_auto_f(0, st)
      if (present(par)) then
         call par%property_lists(fapl, file%dxpl)
         call h5fcreate_f(name, H5F_ACC_TRUNC_F, file%id, st, H5P_DEFAULT_F, fapl)
         call h5pclose_f(fapl, s2)
         if (st /= 0) then
            call h5pclose_f(file%dxpl, s2)
            file%dxpl = -1
            call fatal_error(error, name//": cannot create HDF5 file (parallel HDF5)", error_code%io)
            return
         end if
         file%parallel = .true.
         file%rank = par%rank
         file%nranks = par%nranks
      else
         call h5pcreate_f(H5P_FILE_ACCESS_F, fapl, st)
         call h5pset_fapl_core_f(fapl, int(4 * 1024 * 1024, size_t), .false., st)
         call h5fcreate_f(name, H5F_ACC_TRUNC_F, file%id, st, H5P_DEFAULT_F, fapl)
         call h5pclose_f(fapl, s2)
         if (st /= 0) then
            call fatal_error(error, name//": cannot create HDF5 file", error_code%io)
            return
         end if
         file%in_memory = .true.
      end if
      call h5pcreate_f(H5P_DATASET_CREATE_F, file%dcpl, st)
      call h5pset_obj_track_times_f(file%dcpl, .false., st)
      call h5pcreate_f(H5P_GROUP_CREATE_F, file%gcpl, st)
      call h5pset_obj_track_times_f(file%gcpl, .false., st)
   end subroutine h5_create

   !> Open an existing file read-only.
   subroutine h5_open_read(file, name, error)
      !> Handle.
      type(h5_file_type), intent(out) :: file
      !> File name.
      character(len=*), intent(in) :: name
      !> Error: missing or not HDF5.
      type(error_type), allocatable, intent(out) :: error
      integer :: st
      logical :: exists
      file%name = name
      inquire (file=name, exist=exists)
      if (.not. exists) then
         call fatal_error(error, name//": no such model file", error_code%io)
         return
      end if
      call h5open_f(st)
      call h5eset_auto_f(0, st)   ! errors are reported through error_type, not HDF5's stack dump
      call h5fopen_f(name, H5F_ACC_RDONLY_F, file%id, st)
      if (st /= 0) call fatal_error(error, name//": not a readable HDF5 file", error_code%io)
   end subroutine h5_open_read

   !> Close a file; a file created by h5_create is written to disk here (every write and the close
   !> checked; errors name the file and the reason).
   subroutine h5_close(file, error)
      use hdf5, only: h5fflush_f, h5fget_file_image_f, H5F_SCOPE_GLOBAL_F
      !> Handle.
      type(h5_file_type), intent(inout) :: file
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      integer :: st, unit, s2
      integer(size_t) :: n
      character(kind=c_char), allocatable, target :: image(:)
      type(c_ptr) :: p
      character(len=512) :: msg
      if (file%dcpl >= 0) call h5pclose_f(file%dcpl, st)
      if (file%gcpl >= 0) call h5pclose_f(file%gcpl, st)
      if (file%dxpl >= 0) call h5pclose_f(file%dxpl, st)
      file%dcpl = -1
      file%gcpl = -1
      file%dxpl = -1
      if (file%in_memory) then
         call h5fflush_f(file%id, H5F_SCOPE_GLOBAL_F, st)
         p = c_null_ptr
         if (st == 0) call h5fget_file_image_f(file%id, p, 0_size_t, st, n)
         if (st == 0) then
            allocate (image(max(1_size_t, n)))
            p = c_loc(image)
            call h5fget_file_image_f(file%id, p, n, st)
         end if
         call h5fclose_f(file%id, s2)
         file%id = -1
         file%in_memory = .false.
         if (st /= 0) then
            call fatal_error(error, file%name//": cannot build the HDF5 file image", error_code%io)
            return
         end if
         open (newunit=unit, file=file%name, access="stream", form="unformatted", status="replace", &
               action="write", iostat=st, iomsg=msg)
         if (st == 0) write (unit, iostat=st, iomsg=msg) image(:n)
         if (st == 0) flush (unit, iostat=st, iomsg=msg)
         if (st == 0) then
            close (unit, iostat=st, iomsg=msg)
         else
            close (unit, iostat=s2)
         end if
         if (st /= 0) then
            call fatal_error(error, file%name//": writing the HDF5 file failed ("//trim(msg)//")", error_code%io)
         else if (file_size(file%name) /= int(n, i8)) then
            ! gfortran does not report a short write through iostat: compare with the size on disk
            call fatal_error(error, file%name//": writing the HDF5 file failed: "//int_text(int(max(0_i8, &
                             file_size(file%name)) / 1024))//" of "//int_text(int(n / 1024))// &
                             " kB reached the disk (disk full or file-size limit)", error_code%io)
         end if
         return
      end if
      call h5fclose_f(file%id, st)
      if (st /= 0) call fatal_error(error, file%name//": error closing HDF5 file", error_code%io)
      file%id = -1
   end subroutine h5_close

   !> True if the link `path` exists (parent groups must exist).
   function h5_exists(file, path) result(exists)
      !> Handle.
      type(h5_file_type), intent(in) :: file
      !> Object path.
      character(len=*), intent(in) :: path
      logical :: exists
      integer :: st
      call h5lexists_f(file%id, path, exists, st)
      if (st /= 0) exists = .false.
   end function h5_exists

   !> Create a group.
   subroutine h5_group(file, path, error)
      !> Handle.
      type(h5_file_type), intent(in) :: file
      !> Group path.
      character(len=*), intent(in) :: path
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: gid
      integer :: st
      call h5gcreate_f(file%id, path, gid, st, gcpl_id=file%gcpl)
      if (st /= 0) then
         call fail(error, file, path, "cannot create group")
         return
      end if
      call h5gclose_f(gid, st)
   end subroutine h5_group

   subroutine make_dataset(file, path, dtype, dims, dset, space, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer(hid_t), intent(in) :: dtype
      integer(hsize_t), intent(in) :: dims(:)
      integer(hid_t), intent(out) :: dset, space
      type(error_type), allocatable, intent(out) :: error
      integer :: st
      if (size(dims) == 0) then
         call h5screate_f(H5S_SCALAR_F, space, st)
      else
         call h5screate_simple_f(size(dims), dims, space, st)
      end if
      call h5dcreate_f(file%id, path, dtype, space, dset, st, dcpl_id=file%dcpl)
      if (st /= 0) call fail(error, file, path, "cannot create dataset")
   end subroutine make_dataset

   subroutine finish(file, path, st, dset, space, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer, intent(in) :: st
      integer(hid_t), intent(in) :: dset, space
      type(error_type), allocatable, intent(out) :: error
      integer :: s2
      call h5dclose_f(dset, s2)
      call h5sclose_f(space, s2)
      if (st /= 0) call fail(error, file, path, "write failed")
   end subroutine finish

   !> Create dataset `path` for an array of shape `xshape` (its last dimension `total` when
   !> given) and select what this process writes (`select_part` in a parallel file; all
   !> otherwise): the handles and the status in w.
   subroutine start_write(file, path, dtype, xshape, w, error, split, offset, total)
      use hdf5, only: H5S_ALL_F, H5P_DEFAULT_F
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer(hid_t), intent(in) :: dtype
      integer(hsize_t), intent(in) :: xshape(:)
      type(dataset_write_type), intent(out) :: w
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in), optional :: split
      integer(i8), intent(in), optional :: offset, total
      integer(hsize_t) :: dims(size(xshape))
      dims = xshape
      if (present(total)) dims(size(dims)) = total
      call make_dataset(file, path, dtype, dims, w%dset, w%space, error)
      if (allocated(error)) return
      w%st = 0
      if (file%parallel) then
         call select_part(file, w%space, dims, split, w%st, offset, int(xshape(size(xshape)), i8), w%mspace)
         w%fspace = w%space
         w%xfer = file%dxpl
      else
         w%mspace = H5S_ALL_F
         w%fspace = H5S_ALL_F
         w%xfer = H5P_DEFAULT_F
      end if
   end subroutine start_write

   !> Close what `start_write` opened; an error when the selection or the write failed.
   subroutine end_write(file, path, w, error)
      use hdf5, only: H5S_ALL_F
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      type(dataset_write_type), intent(in) :: w
      type(error_type), allocatable, intent(out) :: error
      integer :: s2
      ! a failed selection or write keeps its status
      if (w%mspace /= w%space .and. w%mspace /= H5S_ALL_F) call h5sclose_f(w%mspace, s2)
      call finish(file, path, w%st, w%dset, w%space, error)
   end subroutine end_write

   subroutine write_real1(file, path, x, error, split, offset, total)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), intent(in) :: x(:)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in), optional :: split
      integer(i8), intent(in), optional :: offset, total
      type(dataset_write_type) :: w
      call start_write(file, path, H5T_NATIVE_DOUBLE, shape(x, hsize_t), w, error, split, offset, total)
      if (allocated(error)) return
      if (w%st == 0) call h5dwrite_f(w%dset, H5T_NATIVE_DOUBLE, x, shape(x, hsize_t), w%st, mem_space_id=w%mspace, &
                                     file_space_id=w%fspace, xfer_prp=w%xfer)
      call end_write(file, path, w, error)
   end subroutine write_real1

   subroutine write_real2(file, path, x, error, split, offset, total)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), intent(in) :: x(:, :)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in), optional :: split
      integer(i8), intent(in), optional :: offset, total
      type(dataset_write_type) :: w
      call start_write(file, path, H5T_NATIVE_DOUBLE, shape(x, hsize_t), w, error, split, offset, total)
      if (allocated(error)) return
      if (w%st == 0) call h5dwrite_f(w%dset, H5T_NATIVE_DOUBLE, x, shape(x, hsize_t), w%st, mem_space_id=w%mspace, &
                                     file_space_id=w%fspace, xfer_prp=w%xfer)
      call end_write(file, path, w, error)
   end subroutine write_real2

   subroutine write_real3(file, path, x, error, split, offset, total)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), intent(in) :: x(:, :, :)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in), optional :: split
      integer(i8), intent(in), optional :: offset, total
      type(dataset_write_type) :: w
      call start_write(file, path, H5T_NATIVE_DOUBLE, shape(x, hsize_t), w, error, split, offset, total)
      if (allocated(error)) return
      if (w%st == 0) call h5dwrite_f(w%dset, H5T_NATIVE_DOUBLE, x, shape(x, hsize_t), w%st, mem_space_id=w%mspace, &
                                     file_space_id=w%fspace, xfer_prp=w%xfer)
      call end_write(file, path, w, error)
   end subroutine write_real3

   subroutine write_int1(file, path, x, error, split, offset, total)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer, intent(in) :: x(:)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in), optional :: split
      integer(i8), intent(in), optional :: offset, total
      type(dataset_write_type) :: w
      call start_write(file, path, H5T_NATIVE_INTEGER, shape(x, hsize_t), w, error, split, offset, total)
      if (allocated(error)) return
      if (w%st == 0) call h5dwrite_f(w%dset, H5T_NATIVE_INTEGER, x, shape(x, hsize_t), w%st, mem_space_id=w%mspace, &
                                     file_space_id=w%fspace, xfer_prp=w%xfer)
      call end_write(file, path, w, error)
   end subroutine write_int1

   !> This process' part of a dataset of shape `dims` written in parallel, selected in the file
   !> dataspace `space`: with `split`, a contiguous block of the last dimension, either
   !> lo+1..hi, lo = n rank / nranks (every process holds the whole array, used as the memory
   !> dataspace: mspace = space), or, with `offset` >= 0, the `held` entries offset+1..offset+held
   !> that this process holds (mspace: a new dataspace of the array's shape, the caller closes it
   !> when it differs from space); otherwise everything on process 0 and nothing on the others.
   subroutine select_part(file, space, dims, split, st, offset, held, mspace)
      use hdf5, only: h5sselect_none_f, h5sselect_hyperslab_f, H5S_SELECT_SET_F
      type(h5_file_type), intent(in) :: file
      integer(hid_t), intent(in) :: space
      integer(hsize_t), intent(in) :: dims(:)
      logical, intent(in), optional :: split
      integer, intent(out) :: st
      integer(i8), intent(in), optional :: offset, held
      integer(hid_t), intent(out), optional :: mspace
      integer(hsize_t) :: start(size(dims)), count(size(dims)), n, lo, hi, mdims(size(dims))
      logical :: by_block, held_only
      st = 0
      if (present(mspace)) mspace = space
      by_block = .false.
      if (present(split)) by_block = split .and. size(dims) > 0
      if (.not. by_block) then
         if (file%rank /= 0) call h5sselect_none_f(space, st)
         return
      end if
      n = dims(size(dims))
      held_only = .false.
      if (present(offset) .and. present(held) .and. present(mspace)) held_only = offset >= 0
      if (held_only) then
         lo = offset
         hi = offset + held
         mdims = dims
         mdims(size(dims)) = max(1_i8, held)
         call h5screate_simple_f(size(dims), mdims, mspace, st)
         if (st /= 0) then
            mspace = space
            return
         end if
         if (held == 0) call h5sselect_none_f(mspace, st)
      else
         lo = block_start(int(n, i8), file%rank, file%nranks)
         hi = block_start(int(n, i8), file%rank + 1, file%nranks)
      end if
      if (hi <= lo) then
         call h5sselect_none_f(space, st)
         return
      end if
      start = 0
      count = dims
      start(size(dims)) = lo
      count(size(dims)) = hi - lo
      call h5sselect_hyperslab_f(space, H5S_SELECT_SET_F, start, count, st)
   end subroutine select_part

   !> Where process r's block of n entries split over nranks processes starts (0-based): n r /
   !> nranks, rounded down; block r is start(r) + 1 .. start(r + 1) (the datasets written with
   !> `split`, and the MPI build's particles by global id).
   pure integer(i8) function block_start(n, r, nranks) result(lo)
      !> Entries.
      integer(i8), intent(in) :: n
      !> Process (0 .. nranks; nranks gives n) and processes.
      integer, intent(in) :: r, nranks
      lo = n * r / max(1, nranks)
   end function block_start

   subroutine string_type(len, dtype)
      integer, intent(in) :: len
      integer(hid_t), intent(out) :: dtype
      integer :: st
      call h5tcopy_f(H5T_FORTRAN_S1, dtype, st)
      call h5tset_size_f(dtype, int(max(1, len), size_t), st)
   end subroutine string_type

   subroutine write_string(file, path, text, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      character(len=*), intent(in) :: text
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: dset, space, dtype
      integer(hsize_t) :: none(0)
      integer :: st
      call string_type(len(text), dtype)
      call make_dataset(file, path, dtype, none, dset, space, error)
      if (allocated(error)) return
      if (file%parallel) then
         call select_part(file, space, none, .false., st)
         if (st == 0) call h5dwrite_f(dset, dtype, text, [1_hsize_t], st, mem_space_id=space, &
                                      file_space_id=space, xfer_prp=file%dxpl)
      else
         call h5dwrite_f(dset, dtype, text, [1_hsize_t], st)
      end if
      call h5tclose_f(dtype, st)
      call finish(file, path, st, dset, space, error)
   end subroutine write_string

   subroutine write_strings(file, path, text, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      character(len=*), intent(in) :: text(:)
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: dset, space, dtype
      integer :: st
      call string_type(len(text), dtype)
      call make_dataset(file, path, dtype, shape(text, hsize_t), dset, space, error)
      if (allocated(error)) return
      if (file%parallel) then
         call select_part(file, space, shape(text, hsize_t), .false., st)
         if (st == 0) call h5dwrite_f(dset, dtype, text, shape(text, hsize_t), st, mem_space_id=space, &
                                      file_space_id=space, xfer_prp=file%dxpl)
      else
         call h5dwrite_f(dset, dtype, text, shape(text, hsize_t), st)
      end if
      call h5tclose_f(dtype, st)
      call finish(file, path, st, dset, space, error)
   end subroutine write_strings

   subroutine attr_common(file, path, name, dtype, aid, space, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer(hid_t), intent(in) :: dtype
      integer(hid_t), intent(out) :: aid, space
      type(error_type), allocatable, intent(out) :: error
      integer :: st
      call h5screate_f(H5S_SCALAR_F, space, st)
      call h5acreate_by_path(file, path, name, dtype, space, aid, st)
      if (st /= 0) call fail(error, file, path//"@"//name, "cannot create attribute")
   end subroutine attr_common

   subroutine h5acreate_by_path(file, path, name, dtype, space, aid, st)
      use hdf5, only: h5oopen_f, h5oclose_f
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer(hid_t), intent(in) :: dtype, space
      integer(hid_t), intent(out) :: aid
      integer, intent(out) :: st
      integer(hid_t) :: oid
      integer :: s2
      call h5oopen_f(file%id, path, oid, st)
      if (st /= 0) return
      call h5acreate_f(oid, name, dtype, space, aid, st)
      call h5oclose_f(oid, s2)
   end subroutine h5acreate_by_path

   subroutine attr_int(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer, intent(in) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: aid, space
      integer :: st, s2
      call attr_common(file, path, name, H5T_NATIVE_INTEGER, aid, space, error)
      if (allocated(error)) return
      call h5awrite_f(aid, H5T_NATIVE_INTEGER, val, [1_hsize_t], st)
      call h5aclose_f(aid, s2)
      call h5sclose_f(space, s2)
      if (st /= 0) call fail(error, file, path//"@"//name, "write failed")
   end subroutine attr_int

   !> A 64-bit integer attribute (stored as int64, e.g. the seed).
   subroutine attr_int64(file, path, name, val, error)
      use, intrinsic :: iso_c_binding, only: c_ptr, c_loc
      use hdf5, only: h5kind_to_type, H5_INTEGER_KIND
      use anm_core_kinds, only: i8
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer(i8), intent(in) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(i8), target :: buf
      integer(hid_t) :: aid, space, dtype
      type(c_ptr) :: ptr
      integer :: st
      dtype = h5kind_to_type(i8, H5_INTEGER_KIND)
      call attr_common(file, path, name, dtype, aid, space, error)
      if (allocated(error)) return
      buf = val
      ptr = c_loc(buf)
      call h5awrite_f(aid, dtype, ptr, st)
      call h5aclose_f(aid, st)
      call h5sclose_f(space, st)
      if (st /= 0) call fail(error, file, path//"@"//name, "write failed")
   end subroutine attr_int64

   subroutine attr_real(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      real(wp), intent(in) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: aid, space
      integer :: st, s2
      call attr_common(file, path, name, H5T_NATIVE_DOUBLE, aid, space, error)
      if (allocated(error)) return
      call h5awrite_f(aid, H5T_NATIVE_DOUBLE, val, [1_hsize_t], st)
      call h5aclose_f(aid, s2)
      call h5sclose_f(space, s2)
      if (st /= 0) call fail(error, file, path//"@"//name, "write failed")
   end subroutine attr_real

   subroutine attr_string(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      character(len=*), intent(in) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: aid, space, dtype
      integer :: st, s2
      call string_type(len(val), dtype)
      call attr_common(file, path, name, dtype, aid, space, error)
      if (allocated(error)) return
      call h5awrite_f(aid, dtype, val, [1_hsize_t], st)
      call h5aclose_f(aid, s2)
      call h5sclose_f(space, s2)
      if (st /= 0) call fail(error, file, path//"@"//name, "write failed")
      call h5tclose_f(dtype, s2)
   end subroutine attr_string

   !> Dimensions of a dataset (Fortran order); error if it does not exist.
   subroutine h5_dims(file, path, dims, error)
      !> Handle.
      type(h5_file_type), intent(in) :: file
      !> Dataset path.
      character(len=*), intent(in) :: path
      !> Dimensions (Fortran order; reversed with respect to numpy's shape).
      integer, allocatable, intent(out) :: dims(:)
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: dset, space
      integer(hsize_t) :: d(7), mx(7)
      integer :: st, rank
      call h5dopen_f(file%id, path, dset, st)
      if (st /= 0) then
         call fail(error, file, path, "missing dataset")
         return
      end if
      call h5dget_space_f(dset, space, st)
      call h5sget_simple_extent_ndims_f(space, rank, st)
      call h5sget_simple_extent_dims_f(space, d(1:rank), mx(1:rank), st)
      dims = int(d(1:rank))
      call h5sclose_f(space, st)
      call h5dclose_f(dset, st)
   end subroutine h5_dims

   subroutine open_dataset(file, path, dset, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer(hid_t), intent(out) :: dset
      type(error_type), allocatable, intent(out) :: error
      integer :: st
      call h5dopen_f(file%id, path, dset, st)
      if (st /= 0) call fail(error, file, path, "missing dataset")
   end subroutine open_dataset

   !> Open a dataset for reading after checking that it exists and has the expected rank.
   subroutine open_rank(file, path, rank, dims, dset, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer, intent(in) :: rank
      integer, allocatable, intent(out) :: dims(:)
      integer(hid_t), intent(out) :: dset
      type(error_type), allocatable, intent(out) :: error
      call h5_dims(file, path, dims, error)
      if (allocated(error)) return
      if (size(dims) /= rank) then
         call fail(error, file, path, "expected a rank-"//achar(48 + rank)//" dataset")
         return
      end if
      call open_dataset(file, path, dset, error)
   end subroutine open_rank

   !> Close a dataset after a read whose status is st.
   subroutine close_read(file, path, dset, st, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer(hid_t), intent(in) :: dset
      integer, intent(in) :: st
      type(error_type), allocatable, intent(out) :: error
      integer :: s2
      call h5dclose_f(dset, s2)
      if (st /= 0) call fail(error, file, path, "read failed")
   end subroutine close_read

   subroutine read_real1(file, path, x, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), allocatable, intent(out) :: x(:)
      type(error_type), allocatable, intent(out) :: error
      integer, allocatable :: dims(:)
      integer(hid_t) :: dset
      integer :: st
      call open_rank(file, path, 1, dims, dset, error)
      if (allocated(error)) return
      allocate (x(dims(1)))
      call h5dread_f(dset, H5T_NATIVE_DOUBLE, x, int(dims, hsize_t), st)
      call close_read(file, path, dset, st, error)
   end subroutine read_real1

   subroutine read_real2(file, path, x, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), allocatable, intent(out) :: x(:, :)
      type(error_type), allocatable, intent(out) :: error
      integer, allocatable :: dims(:)
      integer(hid_t) :: dset
      integer :: st
      call open_rank(file, path, 2, dims, dset, error)
      if (allocated(error)) return
      allocate (x(dims(1), dims(2)))
      call h5dread_f(dset, H5T_NATIVE_DOUBLE, x, int(dims, hsize_t), st)
      call close_read(file, path, dset, st, error)
   end subroutine read_real2

   subroutine read_real3(file, path, x, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      real(wp), allocatable, intent(out) :: x(:, :, :)
      type(error_type), allocatable, intent(out) :: error
      integer, allocatable :: dims(:)
      integer(hid_t) :: dset
      integer :: st
      call open_rank(file, path, 3, dims, dset, error)
      if (allocated(error)) return
      allocate (x(dims(1), dims(2), dims(3)))
      call h5dread_f(dset, H5T_NATIVE_DOUBLE, x, int(dims, hsize_t), st)
      call close_read(file, path, dset, st, error)
   end subroutine read_real3

   subroutine read_int1(file, path, x, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer, allocatable, intent(out) :: x(:)
      type(error_type), allocatable, intent(out) :: error
      integer, allocatable :: dims(:)
      integer(hid_t) :: dset
      integer :: st
      call open_rank(file, path, 1, dims, dset, error)
      if (allocated(error)) return
      allocate (x(dims(1)))
      call h5dread_f(dset, H5T_NATIVE_INTEGER, x, int(dims, hsize_t), st)
      call close_read(file, path, dset, st, error)
   end subroutine read_int1

   subroutine read_string(file, path, text, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      character(len=:), allocatable, intent(out) :: text
      type(error_type), allocatable, intent(out) :: error
      type(h5_text_type), allocatable :: texts(:)
      integer(hid_t) :: dset
      call open_dataset(file, path, dset, error)
      if (allocated(error)) return
      call read_text(file, path, dset, .false., texts, error)
      if (allocated(error)) return
      if (size(texts) /= 1) then
         call fail(error, file, path, "expected one string, found "//int_text(size(texts)))
         return
      end if
      text = texts(1)%s
   end subroutine read_string

   !> Read a rank-1 dataset of strings, fixed- or variable-length (any writer: Anm writes fixed-length
   !> ones, h5py variable-length UTF-8 ones by default), into `text` (each truncated to len(text);
   !> trailing NUL and blank padding removed).
   subroutine h5_read_strings(file, path, text, error)
      !> Handle.
      type(h5_file_type), intent(in) :: file
      !> Dataset path.
      character(len=*), intent(in) :: path
      !> Strings read.
      character(len=*), allocatable, intent(out) :: text(:)
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      type(h5_text_type), allocatable :: texts(:)
      integer(hid_t) :: dset
      integer, allocatable :: dims(:)
      integer :: i
      call h5_dims(file, path, dims, error)
      if (allocated(error)) return
      if (size(dims) /= 1) then
         call fail(error, file, path, "expected a rank-1 dataset of strings")
         return
      end if
      call open_dataset(file, path, dset, error)
      if (allocated(error)) return
      call read_text(file, path, dset, .false., texts, error)
      if (allocated(error)) return
      allocate (text(size(texts)))
      do i = 1, size(texts)
         text(i) = texts(i)%s
      end do
   end subroutine h5_read_strings

   !> Read every string of a dataset or attribute `id` (closed on return) whether stored with a
   !> fixed length (NUL- or space-padded) or a variable length; errors when it holds no strings.
   subroutine read_text(file, path, id, is_attr, texts, error)
      use hdf5, only: h5aget_type_f, h5aget_space_f, h5sget_simple_extent_npoints_f, h5tget_class_f, &
         & h5tis_variable_str_f, h5dvlen_reclaim_f, H5T_STRING_F, H5P_DEFAULT_F
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path
      integer(hid_t), intent(in) :: id
      logical, intent(in) :: is_attr
      type(h5_text_type), allocatable, intent(out) :: texts(:)
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: dtype, space
      integer(hsize_t) :: npoints
      integer(size_t) :: sz
      integer :: st, s2, cls, i, n
      logical :: vlen
      type(c_ptr), allocatable, target :: ptrs(:)
      type(c_ptr) :: bufp
      character(kind=c_char), allocatable, target :: bytes(:)
      character(kind=c_char), pointer :: chars(:)

      if (is_attr) then
         call h5aget_type_f(id, dtype, st)
         call h5aget_space_f(id, space, s2)
      else
         call h5dget_type_f(id, dtype, st)
         call h5dget_space_f(id, space, s2)
      end if
      call h5tget_class_f(dtype, cls, st)
      if (st /= 0 .or. cls /= H5T_STRING_F) then
         call fail(error, file, path, "expected a string, found another data type")
         goto 90
      end if
      call h5sget_simple_extent_npoints_f(space, npoints, st)
      n = int(npoints)
      allocate (texts(n))
      call h5tis_variable_str_f(dtype, vlen, st)
      if (vlen) then
         allocate (ptrs(max(1, n)))
         ptrs = c_null_ptr
         if (is_attr) then
            bufp = c_loc(ptrs)
            call h5aread_f(id, dtype, bufp, st)
         else
            bufp = c_loc(ptrs)
            call h5dread_f(id, dtype, bufp, st)
         end if
         if (st /= 0) then
            call fail(error, file, path, "read failed (variable-length string)")
            goto 90
         end if
         do i = 1, n
            if (c_associated(ptrs(i))) then
               call c_f_pointer(ptrs(i), chars, [c_strlen(ptrs(i))])
               texts(i)%s = from_chars(chars)
            else
               texts(i)%s = ""
            end if
         end do
         bufp = c_loc(ptrs)
         call h5dvlen_reclaim_f(dtype, space, H5P_DEFAULT_F, bufp, s2)
      else
         call h5tget_size_f(dtype, sz, st)
         allocate (bytes(max(1, int(sz) * n)))
         if (is_attr) then
            bufp = c_loc(bytes)
            call h5aread_f(id, dtype, bufp, st)
         else
            bufp = c_loc(bytes)
            call h5dread_f(id, dtype, bufp, st)
         end if
         if (st /= 0) then
            call fail(error, file, path, "read failed (fixed-length string)")
            goto 90
         end if
         do i = 1, n
            texts(i)%s = from_chars(bytes((i - 1) * int(sz) + 1:i * int(sz)))
         end do
      end if
90    call h5tclose_f(dtype, s2)
      call h5sclose_f(space, s2)
      if (is_attr) then
         call h5aclose_f(id, s2)
      else
         call h5dclose_f(id, s2)
      end if
   end subroutine read_text

   !> Text of a byte array up to its first NUL, trailing blanks removed.
   pure function from_chars(chars) result(text)
      character(kind=c_char), intent(in) :: chars(:)
      character(len=:), allocatable :: text
      integer :: i, n
      n = size(chars)
      do i = 1, size(chars)
         if (chars(i) == c_null_char) then
            n = i - 1
            exit
         end if
      end do
      allocate (character(len=n) :: text)
      do i = 1, n
         text(i:i) = chars(i)
      end do
      text = trim(text)
   end function from_chars

   pure function int_text(i) result(s)
      integer, intent(in) :: i
      character(len=:), allocatable :: s
      character(len=24) :: buf
      write (buf, '(i0)') i
      s = trim(buf)
   end function int_text

   subroutine open_attr(file, path, name, aid, error)
      use hdf5, only: h5oopen_f, h5oclose_f
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer(hid_t), intent(out) :: aid
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: oid
      integer :: st, s2
      logical :: exists
      call h5oopen_f(file%id, path, oid, st)
      if (st /= 0) then
         call fail(error, file, path, "missing object")
         return
      end if
      call h5aexists_f(oid, name, exists, st)
      if (.not. exists) then
         call h5oclose_f(oid, s2)
         call fail(error, file, path//"@"//name, "missing attribute")
         return
      end if
      call h5aopen_f(oid, name, aid, st)
      call h5oclose_f(oid, s2)
   end subroutine open_attr

   subroutine read_attr_int(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      integer, intent(out) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: aid
      integer :: st, s2
      val = 0
      call open_attr(file, path, name, aid, error)
      if (allocated(error)) return
      call h5aread_f(aid, H5T_NATIVE_INTEGER, val, [1_hsize_t], st)
      call h5aclose_f(aid, s2)
      if (st /= 0) call fail(error, file, path//"@"//name, "read failed (expected an integer)")
   end subroutine read_attr_int

   subroutine read_attr_real(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      real(wp), intent(out) :: val
      type(error_type), allocatable, intent(out) :: error
      integer(hid_t) :: aid
      integer :: st, s2
      val = 0.0_wp
      call open_attr(file, path, name, aid, error)
      if (allocated(error)) return
      call h5aread_f(aid, H5T_NATIVE_DOUBLE, val, [1_hsize_t], st)
      call h5aclose_f(aid, s2)
      if (st /= 0) call fail(error, file, path//"@"//name, "read failed (expected a number)")
   end subroutine read_attr_real

   subroutine read_attr_string(file, path, name, val, error)
      type(h5_file_type), intent(in) :: file
      character(len=*), intent(in) :: path, name
      character(len=:), allocatable, intent(out) :: val
      type(error_type), allocatable, intent(out) :: error
      type(h5_text_type), allocatable :: texts(:)
      integer(hid_t) :: aid
      call open_attr(file, path, name, aid, error)
      if (allocated(error)) return
      call read_text(file, path//"@"//name, aid, .true., texts, error)
      if (allocated(error)) return
      if (size(texts) /= 1) then
         call fail(error, file, path//"@"//name, "expected one string, found "//int_text(size(texts)))
         return
      end if
      val = texts(1)%s
   end subroutine read_attr_string
end module anm_io_hdf5
