!> The adapter that Python (numpy.f2py) sees: slicing, shells grown for slicing, SH evaluation and
!> shape geometry, over explicit-shape `real(c_double)` / `integer(c_int)` arrays.
!>
!> No derived types or allocatables cross the boundary. Every routine ends with `status` (0 on
!> success, else the anm error code) and `message` (what went wrong, blank on success); the
!> Python side (`anm_post.kernels`) turns a non-zero status into an exception.
!>
!> Shapes are passed as in the model file: coeffs(2, ncoef, nshape) holds Re and Im of a_nm in
!> the NIST line order (n = 0..nmax, m = n..-n; index n^2 + n - m + 1), with nmax(nshape) the
!> highest degree stored per shape. Surfaces for slicing ("forms") are passed in real form,
!> a(0:lmax, 0:lmax, nform), b(...), order(nform) and certified bounds(8, nform) =
!> (r_min, r_max, box_lo(3), box_hi(3)), as returned by `api_particle_forms` and `api_shell_forms`.
!>
!> Usage (Python):
!>     a, b, bounds = _kernels.anm_api_slice.api_particle_forms(coeffs, nmax, fshape, forder, lmax)
module anm_api_slice
   use, intrinsic :: iso_c_binding, only: c_double, c_int
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_core_resources, only: check_memory
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real, sh_truncate, sh_from_rows
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_slicing_plane, only: slice_plane_type, new_slice_plane
   use anm_slicing_form, only: slice_form_type, new_slice_form, new_slice_form_bounds
   use anm_slicing_kernel, only: slice_labels, slice_stats_type
   use anm_slicing_shells, only: build_shell_forms
   use anm_slicing_stack, only: slice_stack_type, new_slice_stack, stack_radii
   use anm_slicing_points, only: point_labels
   implicit none
   private

   public :: api_sh_radius, api_geometry, api_particle_forms, api_shell_forms, api_slice, api_form_radii, &
      & api_point_labels, message_length

   !> Length of the message buffers (written as the literal 512 in the dummy declarations,
   !> which f2py reads without resolving parameters).
   integer, parameter :: message_length = 512

contains

   !> r(u) of shape `ishape` (1-based) truncated at `order`, along ndir body-frame directions.
   subroutine api_sh_radius(ncoef, nshape, coeffs, nmax, ishape, order, ndir, dirs, r, status, message)
      !> Coefficient rows per shape and number of shapes.
      integer(c_int), intent(in) :: ncoef, nshape
      !> Re, Im of a_nm (2, ncoef, nshape), NIST line order.
      real(c_double), intent(in) :: coeffs(2, ncoef, nshape)
      !> Highest degree stored per shape.
      integer(c_int), intent(in) :: nmax(nshape)
      !> Shape (1-based) and order used.
      integer(c_int), intent(in) :: ishape, order
      !> Number of directions.
      integer(c_int), intent(in) :: ndir
      !> Directions (3, ndir), need not be normalised (non-zero).
      real(c_double), intent(in) :: dirs(3, ndir)
      !> r along each direction (shape units).
      real(c_double), intent(out) :: r(ndir)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(sh_expansion_type) :: sh
      integer :: k

      r = 0.0_c_double
      status = 0
      message = ""
      call get_shape(ncoef, nshape, coeffs, nmax, ishape, order, sh, status, message)
      if (status /= 0) return
      if (any(sum(dirs**2, dim=1) <= 0.0_c_double)) then
         call set_error(status, message, 4, "sh_radius: zero direction")
         return
      end if
      do k = 1, ndir
         r(k) = sh%radius_dir(real(dirs(:, k), wp))
      end do
   end subroutine api_sh_radius

   !> Geometry of shapes at given orders: props(:, k) = volume, area, length, width, thickness,
   !> equivalent diameter, rmin, rmax (grid), in shape units.
   subroutine api_geometry(ncoef, nshape, coeffs, nmax, nform, form_shape, form_order, props, status, message)
      !> Coefficient rows per shape and number of shapes.
      integer(c_int), intent(in) :: ncoef, nshape
      !> Re, Im of a_nm (2, ncoef, nshape).
      real(c_double), intent(in) :: coeffs(2, ncoef, nshape)
      !> Highest degree stored per shape.
      integer(c_int), intent(in) :: nmax(nshape)
      !> Number of (shape, order) pairs.
      integer(c_int), intent(in) :: nform
      !> Shape (1-based) and order of each pair.
      integer(c_int), intent(in) :: form_shape(nform), form_order(nform)
      !> Properties (8, nform).
      real(c_double), intent(out) :: props(8, nform)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(sh_expansion_type) :: sh
      type(shape_geometry_type) :: g
      integer :: k

      props = 0.0_c_double
      status = 0
      message = ""
      do k = 1, nform
         call get_shape(ncoef, nshape, coeffs, nmax, form_shape(k), form_order(k), sh, status, message)
         if (status /= 0) return
         call compute_geometry(sh, g)
         props(:, k) = [g%volume, g%area, g%length, g%width, g%thickness, g%equiv_diameter, g%rmin, g%rmax]
      end do
   end subroutine api_geometry

   !> Particle forms: real-form coefficients (padded to lmax) and certified bounds of each
   !> (shape, order) pair.
   subroutine api_particle_forms(ncoef, nshape, coeffs, nmax, nform, form_shape, form_order, lmax, a, b, bounds, &
                                 status, message)
      !> Coefficient rows per shape and number of shapes.
      integer(c_int), intent(in) :: ncoef, nshape
      !> Re, Im of a_nm (2, ncoef, nshape).
      real(c_double), intent(in) :: coeffs(2, ncoef, nshape)
      !> Highest degree stored per shape.
      integer(c_int), intent(in) :: nmax(nshape)
      !> Number of forms.
      integer(c_int), intent(in) :: nform
      !> Shape (1-based) and order of each form (order <= lmax).
      integer(c_int), intent(in) :: form_shape(nform), form_order(nform)
      !> Size of the coefficient arrays.
      integer(c_int), intent(in) :: lmax
      !> Cosine and sine coefficients (0:lmax, 0:lmax, nform).
      real(c_double), intent(out) :: a(0:lmax, 0:lmax, nform), b(0:lmax, 0:lmax, nform)
      !> r_min, r_max, box_lo(3), box_hi(3) per form.
      real(c_double), intent(out) :: bounds(8, nform)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(sh_expansion_type) :: sh
      type(slice_form_type) :: f
      type(error_type), allocatable :: error
      integer(c_int), allocatable :: stat(:)
      character(len=512), allocatable :: msg(:)
      integer :: k

      a = 0.0_c_double
      b = 0.0_c_double
      bounds = 0.0_c_double
      status = 0
      message = ""
      allocate (stat(nform), msg(nform))
      stat = 0
      !$omp parallel do default(none) schedule(dynamic, 1) private(k, sh, f, error) &
      !$omp shared(nform, ncoef, nshape, coeffs, nmax, form_shape, form_order, lmax, a, b, bounds, stat, msg)
      do k = 1, nform
         call get_shape(ncoef, nshape, coeffs, nmax, form_shape(k), form_order(k), sh, stat(k), msg(k))
         if (stat(k) /= 0) cycle
         if (sh%nmax > lmax) then
            call set_error(stat(k), msg(k), 4, "particle_forms: order exceeds lmax")
            cycle
         end if
         call new_slice_form(f, sh, error)
         if (allocated(error)) then
            call set_error(stat(k), msg(k), error%stat, error%message)
            cycle
         end if
         call put_form(f, lmax, a(:, :, k), b(:, :, k), bounds(:, k))
      end do
      !$omp end parallel do
      do k = 1, nform
         if (stat(k) /= 0) then
            call set_error(status, message, stat(k), msg(k))
            return
         end if
      end do
   end subroutine api_particle_forms

   !> Shells grown for slicing: outer surfaces of nlayer layers for each key (shape, order,
   !> cumulative distances in shape units), as forms.
   subroutine api_shell_forms(ncoef, nshape, coeffs, nmax, nkey, key_shape, key_order, nlayer, thickness, lmax, &
                              a, b, order, bounds, status, message)
      !> Coefficient rows per shape and number of shapes.
      integer(c_int), intent(in) :: ncoef, nshape
      !> Re, Im of a_nm (2, ncoef, nshape).
      real(c_double), intent(in) :: coeffs(2, ncoef, nshape)
      !> Highest degree stored per shape.
      integer(c_int), intent(in) :: nmax(nshape)
      !> Number of keys.
      integer(c_int), intent(in) :: nkey
      !> Shape (1-based) and order of each key.
      integer(c_int), intent(in) :: key_shape(nkey), key_order(nkey)
      !> Number of layers.
      integer(c_int), intent(in) :: nlayer
      !> Cumulative distances (nlayer, nkey), shape units, increasing.
      real(c_double), intent(in) :: thickness(nlayer, nkey)
      !> Size of the coefficient arrays (at least the fitted orders: min(119, max(2 order, 24))).
      integer(c_int), intent(in) :: lmax
      !> Coefficients of the outer surfaces (0:lmax, 0:lmax, nlayer, nkey).
      real(c_double), intent(out) :: a(0:lmax, 0:lmax, nlayer, nkey), b(0:lmax, 0:lmax, nlayer, nkey)
      !> Fitted order of each surface.
      integer(c_int), intent(out) :: order(nlayer, nkey)
      !> Certified bounds (8, nlayer, nkey).
      real(c_double), intent(out) :: bounds(8, nlayer, nkey)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(sh_expansion_type), allocatable :: shapes(:), outers(:, :)
      type(slice_form_type) :: f
      type(error_type), allocatable :: error
      integer :: k, l

      a = 0.0_c_double
      b = 0.0_c_double
      order = 0
      bounds = 0.0_c_double
      status = 0
      message = ""
      allocate (shapes(nkey))
      do k = 1, nkey
         call get_shape(ncoef, nshape, coeffs, nmax, key_shape(k), key_order(k), shapes(k), status, message)
         if (status /= 0) return
      end do
      call build_shell_forms(shapes, [(k, k = 1, nkey)], real(thickness, wp), outers, error)
      if (allocated(error)) then
         call set_error(status, message, error%stat, error%message)
         return
      end if
      do k = 1, nkey
         do l = 1, nlayer
            if (outers(l, k)%nmax > lmax) then
               call set_error(status, message, 4, "shell_forms: fitted order exceeds lmax")
               return
            end if
            call new_slice_form(f, outers(l, k), error)
            if (allocated(error)) then
               call set_error(status, message, error%stat, error%message)
               return
            end if
            order(l, k) = outers(l, k)%nmax
            call put_form(f, lmax, a(:, :, l, k), b(:, :, l, k), bounds(:, l, k))
         end do
      end do
   end subroutine api_shell_forms

   !> Label nplane slices of nu x nv pixels (see anm_slicing_kernel). Particle labels are
   !> 1-based ids (0 = matrix), layers 1..nlayer (0 = none), owner the particle of the shell.
   !> stats = (queried, candidates, pixel tests, SH evaluations).
   subroutine api_slice(lmax, nform, a, b, order, bounds, np, form, nlayer, shell_form, center, rotation, scale, &
                        box, periodic, nplane, origin, u, v, nu, nv, pixel, particle, layer, owner, stats, status, &
                        message)
      !> Size of the coefficient arrays and number of forms.
      integer(c_int), intent(in) :: lmax, nform
      !> Form coefficients (0:lmax, 0:lmax, nform).
      real(c_double), intent(in) :: a(0:lmax, 0:lmax, nform), b(0:lmax, 0:lmax, nform)
      !> Order of each form.
      integer(c_int), intent(in) :: order(nform)
      !> Certified bounds (8, nform).
      real(c_double), intent(in) :: bounds(8, nform)
      !> Number of particles.
      integer(c_int), intent(in) :: np
      !> Form of each particle (1-based).
      integer(c_int), intent(in) :: form(np)
      !> Number of shell layers.
      integer(c_int), intent(in) :: nlayer
      !> Form of each particle's layer (nlayer, np), 0 = no shell.
      integer(c_int), intent(in) :: shell_form(nlayer, np)
      !> Centres (3, np), mm.
      real(c_double), intent(in) :: center(3, np)
      !> Rotations body -> world (3, 3, np).
      real(c_double), intent(in) :: rotation(3, 3, np)
      !> mm per shape unit.
      real(c_double), intent(in) :: scale(np)
      !> Box edges (mm).
      real(c_double), intent(in) :: box(3)
      !> 1 for periodic boundaries.
      integer(c_int), intent(in) :: periodic
      !> Number of planes.
      integer(c_int), intent(in) :: nplane
      !> Corner and in-plane axes of each plane (3, nplane).
      real(c_double), intent(in) :: origin(3, nplane), u(3, nplane), v(3, nplane)
      !> Pixels along u and v.
      integer(c_int), intent(in) :: nu, nv
      !> Pixel size R_s (mm per pixel).
      real(c_double), intent(in) :: pixel
      !> Labels (nu, nv, nplane).
      integer(c_int), intent(out) :: particle(nu, nv, nplane), layer(nu, nv, nplane), owner(nu, nv, nplane)
      !> Work counters.
      real(c_double), intent(out) :: stats(4)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(slice_form_type), allocatable :: forms(:)
      type(slice_plane_type), allocatable :: planes(:)
      type(sh_expansion_type) :: sh
      type(slice_stats_type) :: st
      type(error_type), allocatable :: error
      integer, allocatable :: ip(:, :, :), il(:, :, :), io(:, :, :)
      integer :: k, no

      status = 0
      message = ""
      particle = 0
      layer = 0
      owner = 0
      stats = 0.0_c_double
      if (nu < 1 .or. nv < 1 .or. lmax < 0) then
         call set_error(status, message, 4, "slice: pixel counts must be positive")
         return
      end if
      allocate (forms(nform), planes(nplane))
      do k = 1, nform
         no = order(k)
         if (no < 0 .or. no > lmax) then
            call set_error(status, message, 4, "slice: form order out of range 0..lmax")
            return
         end if
         call new_sh_expansion_real(sh, real(a(0:no, 0:no, k), wp), real(b(0:no, 0:no, k), wp))
         call new_slice_form_bounds(forms(k), sh, real(bounds(1, k), wp), real(bounds(2, k), wp), &
                                    real(bounds(3:5, k), wp), real(bounds(6:8, k), wp))
      end do
      do k = 1, nplane
         call new_slice_plane(planes(k), real(origin(:, k), wp), real(u(:, k), wp), real(v(:, k), wp), &
                              [nu * pixel, nv * pixel], real(pixel, wp), error)
         if (allocated(error)) then
            call set_error(status, message, error%stat, error%message)
            return
         end if
      end do
      ! the label arrays (three int32 per pixel) and the kernel's work per pixel: refuse above the memory
      ! available rather than fail in allocate
      call check_memory(real(nu, wp) * real(nv, wp) * real(nplane, wp) * 24.0_wp, "slice of " &
                        //pixels_text(nu, nv, nplane)//" pixels", "the pixel count (a larger pixel size)", error)
      if (allocated(error)) then
         call set_error(status, message, error%stat, error%message)
         return
      end if
      allocate (ip(nu, nv, nplane), il(nu, nv, nplane), io(nu, nv, nplane))
      call slice_labels(planes, forms, form, shell_form, real(center, wp), real(rotation, wp), real(scale, wp), &
                        real(box, wp), periodic /= 0, ip, il, io, st, error)
      if (allocated(error)) then
         call set_error(status, message, error%stat, error%message)
         return
      end if
      particle = ip
      layer = il
      owner = io
      stats = real([st%queried, st%candidates, st%tests, st%evaluations], c_double)
   end subroutine api_slice

   !> Radii of nform forms (sharing one body frame, e.g. a particle and its layers) along ndir
   !> directions, all forms from one Legendre recursion per direction (anm_slicing_stack).
   subroutine api_form_radii(lmax, nform, a, b, order, ndir, dirs, r, status, message)
      !> Size of the coefficient arrays and number of forms.
      integer(c_int), intent(in) :: lmax, nform
      !> Form coefficients (0:lmax, 0:lmax, nform).
      real(c_double), intent(in) :: a(0:lmax, 0:lmax, nform), b(0:lmax, 0:lmax, nform)
      !> Order of each form.
      integer(c_int), intent(in) :: order(nform)
      !> Number of directions.
      integer(c_int), intent(in) :: ndir
      !> Directions (3, ndir), body frame, non-zero (need not be normalised).
      real(c_double), intent(in) :: dirs(3, ndir)
      !> r(ndir, nform) in shape units.
      real(c_double), intent(out) :: r(ndir, nform)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(sh_expansion_type), allocatable :: sh(:)
      type(slice_stack_type) :: stack
      real(wp), allocatable :: rk(:)
      integer :: k, no

      r = 0.0_c_double
      status = 0
      message = ""
      if (nform < 1 .or. lmax < 0) then
         call set_error(status, message, 4, "form_radii: no forms")
         return
      end if
      if (any(sum(dirs**2, dim=1) <= 0.0_c_double)) then
         call set_error(status, message, 4, "form_radii: zero direction")
         return
      end if
      allocate (sh(nform))
      do k = 1, nform
         no = order(k)
         if (no < 0 .or. no > lmax) then
            call set_error(status, message, 4, "form_radii: form order out of range 0..lmax")
            return
         end if
         call new_sh_expansion_real(sh(k), real(a(0:no, 0:no, k), wp), real(b(0:no, 0:no, k), wp))
      end do
      call new_slice_stack(stack, sh)
      !$omp parallel default(none) private(k, rk) shared(stack, ndir, dirs, r)
      allocate (rk(stack%npad))
      !$omp do schedule(static)
      do k = 1, ndir
         call stack_radii(stack, real(dirs(:, k), wp), rk)
         r(k, :) = rk(1:stack%nform)
      end do
      !$omp end do
      !$omp end parallel
   end subroutine api_form_radii

   !> Label npoint points with a particle containing them (anm_slicing_points): 1-based particle
   !> id, 0 for none.
   subroutine api_point_labels(lmax, nform, a, b, order, bounds, np, form, center, rotation, scale, box, periodic, &
                               npoint, points, label, status, message)
      !> Size of the coefficient arrays and number of forms.
      integer(c_int), intent(in) :: lmax, nform
      !> Form coefficients (0:lmax, 0:lmax, nform).
      real(c_double), intent(in) :: a(0:lmax, 0:lmax, nform), b(0:lmax, 0:lmax, nform)
      !> Order of each form.
      integer(c_int), intent(in) :: order(nform)
      !> Certified bounds (8, nform).
      real(c_double), intent(in) :: bounds(8, nform)
      !> Number of particles.
      integer(c_int), intent(in) :: np
      !> Form of each particle (1-based).
      integer(c_int), intent(in) :: form(np)
      !> Centres (3, np), mm.
      real(c_double), intent(in) :: center(3, np)
      !> Rotations body -> world (3, 3, np).
      real(c_double), intent(in) :: rotation(3, 3, np)
      !> mm per shape unit.
      real(c_double), intent(in) :: scale(np)
      !> Box edges (mm).
      real(c_double), intent(in) :: box(3)
      !> 1 for periodic boundaries.
      integer(c_int), intent(in) :: periodic
      !> Number of points.
      integer(c_int), intent(in) :: npoint
      !> Points (3, npoint), mm.
      real(c_double), intent(in) :: points(3, npoint)
      !> Particle containing each point (1-based), 0 for none.
      integer(c_int), intent(out) :: label(npoint)
      !> 0 on success.
      integer(c_int), intent(out) :: status
      !> Error message.
      character(len=512), intent(out) :: message
      type(slice_form_type), allocatable :: forms(:)
      type(sh_expansion_type) :: sh
      type(error_type), allocatable :: error
      integer, allocatable :: lab(:)
      integer :: k, no

      status = 0
      message = ""
      label = 0
      allocate (forms(nform))
      do k = 1, nform
         no = order(k)
         if (no < 0 .or. no > lmax) then
            call set_error(status, message, 4, "point_labels: form order out of range 0..lmax")
            return
         end if
         call new_sh_expansion_real(sh, real(a(0:no, 0:no, k), wp), real(b(0:no, 0:no, k), wp))
         call new_slice_form_bounds(forms(k), sh, real(bounds(1, k), wp), real(bounds(2, k), wp), &
                                    real(bounds(3:5, k), wp), real(bounds(6:8, k), wp))
      end do
      allocate (lab(npoint))
      call point_labels(forms, form, real(center, wp), real(rotation, wp), real(scale, wp), real(box, wp), &
                        periodic /= 0, real(points, wp), lab, error)
      if (allocated(error)) then
         call set_error(status, message, error%stat, error%message)
         return
      end if
      label = lab
   end subroutine api_point_labels

   !> Expansion of shape ishape (1-based) truncated at `order`.
   subroutine get_shape(ncoef, nshape, coeffs, nmax, ishape, order, sh, status, message)
      integer(c_int), intent(in) :: ncoef, nshape
      real(c_double), intent(in) :: coeffs(2, ncoef, nshape)
      integer(c_int), intent(in) :: nmax(nshape), ishape, order
      type(sh_expansion_type), intent(out) :: sh
      integer(c_int), intent(out) :: status
      character(len=512), intent(out) :: message
      integer :: nm

      status = 0
      message = ""
      if (ishape < 1 .or. ishape > nshape) then
         call set_error(status, message, 4, "shape index out of range")
         return
      end if
      nm = nmax(ishape)
      if (nm < 0 .or. (nm + 1)**2 > ncoef .or. order < 0) then
         call set_error(status, message, 4, "shape nmax or order out of range (nmax must satisfy (nmax+1)^2 <= ncoef)")
         return
      end if
      sh = sh_truncate(sh_from_rows(coeffs(:, :, ishape), nm), order)
   end subroutine get_shape

   !> Copy a form into the boundary arrays.
   pure subroutine put_form(f, lmax, a, b, bounds)
      type(slice_form_type), intent(in) :: f
      integer(c_int), intent(in) :: lmax
      real(c_double), intent(out) :: a(0:lmax, 0:lmax), b(0:lmax, 0:lmax), bounds(8)
      integer :: no
      no = f%shape%nmax
      a = 0.0_c_double
      b = 0.0_c_double
      a(0:no, 0:no) = f%shape%a
      b(0:no, 0:no) = f%shape%b
      bounds = [f%r_min, f%r_max, f%box_lo, f%box_hi]
   end subroutine put_form

   pure subroutine set_error(status, message, stat, text)
      integer(c_int), intent(out) :: status
      character(len=512), intent(out) :: message
      integer, intent(in) :: stat
      character(len=*), intent(in) :: text
      status = stat
      message = text
   end subroutine set_error
   !> "nu x nv x nplane" as text.
   pure function pixels_text(nu, nv, nplane) result(text)
      integer(c_int), intent(in) :: nu, nv, nplane
      character(len=:), allocatable :: text
      character(len=64) :: buf
      write (buf, '(i0,a,i0,a,i0)') nu, " x ", nv, " x ", nplane
      text = trim(buf)
   end function pixels_text
end module anm_api_slice
