!> Which particle contains a point: the volume counterpart of the slicing kernel, used to measure
!> volume fractions directly in 3D (thesis Eq 3.11 checks the slices against them).
!>
!> The particles are stored in a hierarchical cell list (`anm_neighbours_cell_list`) by their
!> bounding spheres; for each point the cell list returns the particles (and periodic images)
!> whose bounding sphere contains it, and the point-in-surface test |y| <= r(y / |y|) (body frame
!> y = R^T (x - c) / s, certified bounds first) picks the first of them, in the cell list's
!> deterministic order, that contains the point. No planes or pixels are involved. Points are
!> independent, so the OpenMP loop over them gives the same labels with any number of threads.
!>
!> Usage:
!>     call point_labels(forms, form, center, rotation, scale, box, .true., points, label, error)
module anm_slicing_points
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_neighbours_cell_list, only: cell_list_type, new_cell_list
   use anm_slicing_form, only: slice_form_type
   implicit none
   private

   public :: point_labels, form_contains

contains

   !> Label every point with a particle containing it (1-based id, 0 for none).
   subroutine point_labels(forms, form, center, rotation, scale, box, periodic, points, label, error)
      !> Particle surfaces.
      type(slice_form_type), intent(in) :: forms(:)
      !> Per particle: index of its form in `forms`.
      integer, intent(in) :: form(:)
      !> Per particle: centre (3, np), mm, inside the box.
      real(wp), intent(in) :: center(:, :)
      !> Per particle: rotation body -> world (3, 3, np).
      real(wp), intent(in) :: rotation(:, :, :)
      !> Per particle: mm per shape unit.
      real(wp), intent(in) :: scale(:)
      !> Box edges (mm).
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries (points are wrapped into the box, particles seen with their images).
      logical, intent(in) :: periodic
      !> Points (3, npoint), mm.
      real(wp), intent(in) :: points(:, :)
      !> Containing particle of each point (npoint): the first found in cell-list order, 0 if none.
      integer, intent(out) :: label(:)
      !> Error naming the inconsistent argument.
      type(error_type), allocatable, intent(out) :: error
      type(cell_list_type) :: cl
      real(wp), allocatable :: rho(:), shift(:, :)
      integer, allocatable :: cand(:)
      real(wp) :: x(3), y(3)
      integer :: np, i, j, q, nq

      np = size(form)
      label = 0
      if (size(center, 2) /= np .or. size(rotation, 3) /= np .or. size(scale) /= np .or. size(center, 1) /= 3 .or. &
          size(points, 1) /= 3 .or. size(label) /= size(points, 2)) then
         call fatal_error(error, "points: array sizes disagree", error_code%value)
         return
      end if
      if (np == 0) return
      if (minval(form) < 1 .or. maxval(form) > size(forms) .or. .not. all(scale > 0.0_wp) .or. &
          .not. all(box > 0.0_wp)) then
         call fatal_error(error, "points: form index out of range or non-positive scale or box", error_code%value)
         return
      end if
      allocate (rho(np))
      do j = 1, np
         rho(j) = scale(j) * forms(form(j))%r_max
      end do
      call new_cell_list(cl, box, periodic, minval(rho), capacity=np)
      do j = 1, np
         call cl%insert(j, center(:, j), rho(j))
      end do
      !$omp parallel default(none) private(i, j, q, nq, x, y, cand, shift) &
      !$omp shared(cl, forms, form, center, rotation, scale, box, periodic, points, label, rho)
      !$omp do schedule(static, 4096)
      do i = 1, size(points, 2)
         x = points(:, i)
         if (periodic) then
            x = modulo(x, box)
            where (x >= box) x = 0.0_wp
         end if
         call cl%query(x, 0.0_wp, center, rho, cand, shift, nq)
         do q = 1, nq
            j = cand(q)
            y = matmul(x - center(:, j) - shift(:, q), rotation(:, :, j)) / scale(j)
            if (form_contains(forms(form(j)), y)) then
               label(i) = j
               exit
            end if
         end do
      end do
      !$omp end do
      !$omp end parallel
   end subroutine point_labels

   !> Whether the body-frame point y (shape units) lies inside the surface (certified bounds first).
   pure logical function form_contains(f, y) result(isin)
      !> Surface.
      type(slice_form_type), intent(in) :: f
      !> Point.
      real(wp), intent(in) :: y(3)
      real(wp) :: q2
      q2 = y(1)**2 + y(2)**2 + y(3)**2
      if (q2 <= f%r_min**2) then
         isin = .true.
      else if (q2 > f%r_max**2) then
         isin = .false.
      else
         isin = sqrt(q2) <= f%shape%radius_dir(y)
      end if
   end function form_contains
end module anm_slicing_points
