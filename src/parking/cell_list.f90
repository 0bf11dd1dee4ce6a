!> A hierarchical cell list for neighbour search among particles whose sizes differ by orders
!> of magnitude (10 mm aggregates with 0.15 mm sand in one box).
!>
!> Level k has cubic-ish cells of edge at least h_k = h_0 2^k. A particle of bounding radius rho
!> is stored, by its centre, in the lowest level whose cells are at least 2 rho wide, so a query
!> for a sphere (c, rho_q) visits, in each level, only the cells within rho_q + rho_max(level) of
!> c: a few cells per level. A single uniform grid sized for the largest particles would put
!> thousands of sand grains in each cell; one sized for the sand would make every aggregate span
!> thousands of cells. Cost per query: O(levels + neighbours); memory: one integer per particle
!> plus the cell heads (at most 2^24 cells per level; beyond that cells grow, which stays correct).
!>
!> Periodic boxes: displacements use the nearest image; when rho_q + rho_j exceeds half an edge,
!> every image within reach is returned.
!>
!> Usage:
!>     call new_cell_list(cl, box, periodic, rho_min)
!>     call cl%insert(i, center, rho)
!>     call cl%query(center, rho, centers, radii, cand, shift, ncand)
module anm_parking_cell_list
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: cell_list_type, new_cell_list

   integer, parameter :: max_cells_per_level = 2**24

   type :: cell_level_type
      real(wp) :: h(3) = 0.0_wp
      integer :: n(3) = 1
      real(wp) :: rho_max = 0.0_wp
      integer :: count = 0
      integer, allocatable :: head(:)
   end type cell_level_type

   !> The cell list.
   type :: cell_list_type
      !> Box edges (mm).
      real(wp) :: box(3) = 1.0_wp
      !> Periodic boundaries.
      logical :: periodic = .true.
      !> Smallest cell edge h_0.
      real(wp) :: h0 = 1.0_wp
      type(cell_level_type), allocatable :: levels(:)
      !> Next particle in the same cell (0 ends a list), per particle.
      integer, allocatable :: next(:)
   contains
      !> Insert particle i.
      procedure :: insert
      !> Particles whose bounding spheres intersect a query sphere.
      procedure :: query
   end type cell_list_type

contains

   !> An empty cell list for a box; rho_min is the smallest bounding radius expected (smaller ones
   !> still work, in cells larger than needed).
   pure subroutine new_cell_list(cl, box, periodic, rho_min, capacity)
      !> Cell list.
      type(cell_list_type), intent(out) :: cl
      !> Box edges.
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries.
      logical, intent(in) :: periodic
      !> Smallest expected bounding radius.
      real(wp), intent(in) :: rho_min
      !> Initial particle capacity.
      integer, intent(in), optional :: capacity
      integer :: nlev, k, cap
      cl%box = box
      cl%periodic = periodic
      cl%h0 = max(2.0_wp * rho_min, maxval(box) * 1.0e-6_wp)
      nlev = 1
      do while (cl%h0 * 2.0_wp**(nlev - 1) < maxval(box))
         nlev = nlev + 1
      end do
      allocate (cl%levels(nlev))
      do k = 1, nlev
         cl%levels(k)%h = cl%h0 * 2.0_wp**(k - 1)
      end do
      cap = 1024
      if (present(capacity)) cap = max(1, capacity)
      allocate (cl%next(cap))
   end subroutine new_cell_list

   pure integer function level_for(cl, rho) result(k)
      type(cell_list_type), intent(in) :: cl
      real(wp), intent(in) :: rho
      k = 1
      do while (k < size(cl%levels) .and. cl%h0 * 2.0_wp**(k - 1) < 2.0_wp * rho)
         k = k + 1
      end do
   end function level_for

   pure subroutine activate(cl, k)
      type(cell_list_type), intent(inout) :: cl
      integer, intent(in) :: k
      integer :: d
      real(wp) :: want
      if (allocated(cl%levels(k)%head)) return
      want = cl%h0 * 2.0_wp**(k - 1)
      do d = 1, 3
         cl%levels(k)%n(d) = max(1, int(cl%box(d) / want))
      end do
      do while (product(int(cl%levels(k)%n, kind=8)) > max_cells_per_level)
         cl%levels(k)%n = max(1, cl%levels(k)%n / 2)
      end do
      cl%levels(k)%h = cl%box / cl%levels(k)%n
      allocate (cl%levels(k)%head(product(cl%levels(k)%n)))
      cl%levels(k)%head = 0
   end subroutine activate

   pure integer function cell_coord(x, h, n, periodic) result(i)
      real(wp), intent(in) :: x, h
      integer, intent(in) :: n
      logical, intent(in) :: periodic
      i = floor(x / h)
      if (periodic) then
         i = modulo(i, n)
      else
         i = min(n - 1, max(0, i))
      end if
   end function cell_coord

   !> Insert particle i (ids must be inserted once each; the arrays grow as needed).
   pure subroutine insert(self, i, center, rho)
      !> Cell list.
      class(cell_list_type), intent(inout) :: self
      !> Particle id (>= 1).
      integer, intent(in) :: i
      !> Centre (inside the box).
      real(wp), intent(in) :: center(3)
      !> Bounding radius.
      real(wp), intent(in) :: rho
      integer :: k, c(3), cell
      integer, allocatable :: tmp(:)
      if (i > size(self%next)) then
         allocate (tmp(max(2 * size(self%next), i)))
         tmp(:size(self%next)) = self%next
         call move_alloc(tmp, self%next)
      end if
      k = level_for(self, rho)
      call activate(self, k)
      associate (lv => self%levels(k))
         c(1) = cell_coord(center(1), lv%h(1), lv%n(1), self%periodic)
         c(2) = cell_coord(center(2), lv%h(2), lv%n(2), self%periodic)
         c(3) = cell_coord(center(3), lv%h(3), lv%n(3), self%periodic)
         cell = 1 + c(1) + lv%n(1) * (c(2) + lv%n(2) * c(3))
         self%next(i) = lv%head(cell)
         lv%head(cell) = i
         lv%rho_max = max(lv%rho_max, rho)
         lv%count = lv%count + 1
      end associate
   end subroutine insert

   !> Particles j whose bounding spheres (centers(:, j), radii(j)) intersect the sphere
   !> (center, rho): cand(1:ncand) with shift(:, 1:ncand) such that the image of j that meets the
   !> query has centre centers(:, j) + shift. The arrays grow as needed.
   pure subroutine query(self, center, rho, centers, radii, cand, shift, ncand)
      !> Cell list.
      class(cell_list_type), intent(in) :: self
      !> Query centre.
      real(wp), intent(in) :: center(3)
      !> Query radius.
      real(wp), intent(in) :: rho
      !> Centres of the stored particles, (3, n).
      real(wp), intent(in) :: centers(:, :)
      !> Bounding radii of the stored particles.
      real(wp), intent(in) :: radii(:)
      !> Candidate ids.
      integer, allocatable, intent(inout) :: cand(:)
      !> Image shifts, (3, :).
      real(wp), allocatable, intent(inout) :: shift(:, :)
      !> Number of candidates.
      integer, intent(out) :: ncand
      integer :: k, lo(3), hi(3), i1, i2, i3, c1, c2, c3, cell, j, s1, s2, s3, d3
      real(wp) :: reach, d(3), sh(3), lim, half(3)
      logical :: level_images
      ncand = 0
      if (.not. allocated(cand)) allocate (cand(64), shift(3, 64))
      half = 0.5_wp * self%box
      do k = 1, size(self%levels)
         associate (lv => self%levels(k))
            if (lv%count == 0) cycle
            reach = rho + lv%rho_max
            do d3 = 1, 3
               lo(d3) = floor((center(d3) - reach) / lv%h(d3))
               hi(d3) = floor((center(d3) + reach) / lv%h(d3))
               if (self%periodic) then
                  if (hi(d3) - lo(d3) + 1 >= lv%n(d3)) then
                     lo(d3) = 0
                     hi(d3) = lv%n(d3) - 1
                  end if
               else
                  lo(d3) = max(0, lo(d3))
                  hi(d3) = min(lv%n(d3) - 1, hi(d3))
               end if
            end do
            ! a particle can meet several images of another only when the two radii exceed half
            ! an edge; otherwise the nearest image is the only candidate
            level_images = self%periodic .and. any(2.0_wp * reach > self%box)
            do i3 = lo(3), hi(3)
               c3 = wrap_index(i3, lv%n(3))
               do i2 = lo(2), hi(2)
                  c2 = wrap_index(i2, lv%n(2))
                  do i1 = lo(1), hi(1)
                     c1 = wrap_index(i1, lv%n(1))
                     cell = 1 + c1 + lv%n(1) * (c2 + lv%n(2) * c3)
                     j = lv%head(cell)
                     do while (j > 0)
                        lim = rho + radii(j)
                        d = centers(:, j) - center
                        if (level_images) then
                           do s3 = -1, 1
                              do s2 = -1, 1
                                 do s1 = -1, 1
                                    sh = [s1, s2, s3] * self%box
                                    if (sum((d + sh)**2) < lim * lim) call push(cand, shift, ncand, j, sh)
                                 end do
                              end do
                           end do
                        else if (self%periodic) then
                           ! centres lie in the box, so |d| < L: one shift gives the nearest image
                           do d3 = 1, 3
                              if (d(d3) > half(d3)) then
                                 sh(d3) = -self%box(d3)
                              else if (d(d3) < -half(d3)) then
                                 sh(d3) = self%box(d3)
                              else
                                 sh(d3) = 0.0_wp
                              end if
                           end do
                           if (sum((d + sh)**2) < lim * lim) call push(cand, shift, ncand, j, sh)
                        else
                           if (sum(d**2) < lim * lim) call push(cand, shift, ncand, j, [0.0_wp, 0.0_wp, 0.0_wp])
                        end if
                        j = self%next(j)
                     end do
                  end do
               end do
            end do
         end associate
      end do
   end subroutine query

   !> Cell index i wrapped into 0..n-1 (i lies in -n..2n-1 for the ranges used here).
   elemental integer function wrap_index(i, n) result(c)
      integer, intent(in) :: i, n
      c = i
      if (c < 0) then
         c = c + n
         if (c < 0) c = modulo(c, n)
      else if (c >= n) then
         c = c - n
         if (c >= n) c = modulo(c, n)
      end if
   end function wrap_index

   pure subroutine push(cand, shift, ncand, jj, s)
      integer, allocatable, intent(inout) :: cand(:)
      real(wp), allocatable, intent(inout) :: shift(:, :)
      integer, intent(inout) :: ncand
      integer, intent(in) :: jj
      real(wp), intent(in) :: s(3)
      integer, allocatable :: tc(:)
      real(wp), allocatable :: ts(:, :)
      if (ncand == size(cand)) then
         allocate (tc(2 * ncand), ts(3, 2 * ncand))
         tc(:ncand) = cand
         ts(:, :ncand) = shift
         call move_alloc(tc, cand)
         call move_alloc(ts, shift)
      end if
      ncand = ncand + 1
      cand(ncand) = jj
      shift(:, ncand) = s
   end subroutine push
end module anm_parking_cell_list
