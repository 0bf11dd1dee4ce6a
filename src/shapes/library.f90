!> Loading particle shapes: one NIST coefficient file, a folder of them, or the synthetic
!> generator; every loaded shape is checked to be star-shaped.
!>
!> A folder is scanned for files ending in `.dat` whose names do not contain `-geom` (NIST keeps
!> its geometry tables beside the coefficient files), in sorted name order.
!>
!> Usage:
!>     type(shape_set_type) :: set
!>     call load_shapes("../shared/shapes/MA111-7-coarse", set, error)
!>     call synthetic_shapes(par, seed, 24, set, error)
module anm_shapes_library
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: list_directory, is_directory, join_path, base_name, string_type
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_nist, only: read_nist_shape
   use anm_shapes_star, only: check_star_shaped
   use anm_shapes_synthetic, only: synthetic_params_type, make_synthetic_shape
   implicit none
   private

   public :: shape_set_type, load_shapes, load_shape_file, synthetic_shapes, is_shape_file_name

   !> A named list of shapes.
   type :: shape_set_type
      !> Source file names (or generator tags).
      type(string_type), allocatable :: names(:)
      !> Expansions.
      type(sh_expansion_type), allocatable :: shapes(:)
   end type shape_set_type

contains

   !> True for names of coefficient files in a shape folder.
   pure function is_shape_file_name(name) result(ok)
      !> File name.
      character(len=*), intent(in) :: name
      logical :: ok
      integer :: l
      l = len_trim(name)
      ok = .false.
      if (l < 5) return
      ok = name(l - 3:l) == ".dat" .and. index(name, "-geom") == 0
   end function is_shape_file_name

   !> Read one file and check that it is star-shaped.
   subroutine load_shape_file(path, shape, error)
      !> Coefficient file.
      character(len=*), intent(in) :: path
      !> Expansion.
      type(sh_expansion_type), intent(out) :: shape
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      call read_nist_shape(path, shape, error)
      if (allocated(error)) return
      call check_star_shaped(shape, path, error)
   end subroutine load_shape_file

   !> Load a file or every coefficient file of a folder.
   subroutine load_shapes(path, set, error)
      !> File or folder.
      character(len=*), intent(in) :: path
      !> Loaded shapes in sorted name order.
      type(shape_set_type), intent(out) :: set
      !> Error naming the file (and line).
      type(error_type), allocatable, intent(out) :: error
      type(string_type), allocatable :: names(:)
      logical :: exists
      integer :: i, k, nfiles

      if (is_directory(path)) then
         call list_directory(path, names, error)
         if (allocated(error)) return
         nfiles = count([(is_shape_file_name(names(i)%s), i=1, size(names))])
         if (nfiles == 0) then
            call fatal_error(error, trim(path)//": folder holds no shape files (*.dat)", error_code%io)
            return
         end if
         allocate (set%names(nfiles), set%shapes(nfiles))
         k = 0
         do i = 1, size(names)
            if (.not. is_shape_file_name(names(i)%s)) cycle
            k = k + 1
            set%names(k)%s = names(i)%s
            call load_shape_file(join_path(path, names(i)%s), set%shapes(k), error)
            if (allocated(error)) return
         end do
      else
         inquire (file=path, exist=exists)
         if (.not. exists) then
            call fatal_error(error, trim(path)//": no such shape file or folder", error_code%io)
            return
         end if
         allocate (set%names(1), set%shapes(1))
         set%names(1)%s = base_name(path)
         call load_shape_file(path, set%shapes(1), error)
      end if
   end subroutine load_shapes

   !> `count` synthetic shapes numbered 1..count from `seed`, named synthetic-anm-NNNNN.dat.
   subroutine synthetic_shapes(par, seed, count, set, error)
      !> Generator parameters.
      type(synthetic_params_type), intent(in) :: par
      !> Base seed.
      integer(i8), intent(in) :: seed
      !> Number of shapes.
      integer, intent(in) :: count
      !> Generated shapes.
      type(shape_set_type), intent(out) :: set
      !> Error from the generator.
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: errs(:)
      logical, allocatable :: failed(:)
      character(len=32) :: name
      integer :: k

      if (count < 1) then
         call fatal_error(error, "synthetic shapes: count = "//to_string(count)//" must be >= 1", error_code%value)
         return
      end if
      allocate (set%names(count), set%shapes(count), failed(count), errs(count))
      failed = .false.
      !$omp parallel do default(none) shared(par, seed, count, set, failed, errs) private(k, name) &
      !$omp& schedule(dynamic)
      do k = 1, count
         block
            type(error_type), allocatable :: err
            call make_synthetic_shape(par, seed, k, set%shapes(k), err)
            if (allocated(err)) then
               failed(k) = .true.
               errs(k) = err
            end if
         end block
         write (name, '(a,i5.5,a)') "synthetic-anm-", k, ".dat"
         set%names(k)%s = trim(name)
      end do
      !$omp end parallel do
      do k = 1, count
         if (failed(k)) then
            call fatal_error(error, errs(k)%message, errs(k)%stat)
            return
         end if
      end do
   end subroutine synthetic_shapes
end module anm_shapes_library
