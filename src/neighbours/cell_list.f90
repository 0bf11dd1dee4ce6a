!> A hierarchical cell list for neighbour search among particles whose sizes differ by orders
!> of magnitude (10 mm aggregates with 0.15 mm sand in one box).
!>
!> Level k has cubic-ish cells of edge at least h_k = h_0 2^k. A particle of bounding radius rho
!> is stored, by its centre, in the lowest level whose cells are at least 2 rho wide, so a query
!> for a sphere (c, rho_q) visits, in each level, only the cells within rho_q + rho_max(level) of
!> c: a few cells per level. A single uniform grid sized for the largest particles would put
!> thousands of sand grains in each cell; one sized for the sand would make every aggregate span
!> thousands of cells. Cost per query: O(levels + neighbours); memory: about one 128-byte block per
!> occupied cell plus one integer per cell of the levels in use (at most 2^24 cells per level;
!> beyond that cells grow, which stays correct).
!>
!> Storage. A cell holds a chain of blocks of three records; a record is what a query touches of a
!> particle: its centre, its bounding radius (rounded up to single precision), a radius within
!> which another particle certainly overlaps it (rounded down) and its id. One query thus reads one
!> or two cache lines per occupied cell instead of three scattered arrays per particle.
!>
!> Two queries:
!> - `query` returns every particle whose bounding sphere, taken from the caller's arrays,
!>   intersects the query sphere (cells in index order, the most recently inserted first);
!> - `neighbours` reads the stored records, visits the levels from the coarsest and, inside a level,
!>   the query's own cell first and then the cells outwards, and stops at the first particle
!>   certainly overlapping the query (`hit`); otherwise it returns the candidates, whose bounding
!>   spheres intersect the query's, for the exact contact tests.
!>
!> Periodic boxes: displacements use the nearest image; when rho_q + rho_j exceeds half an edge,
!> every image within reach is returned.
!>
!> Blocks are appended to the pool as cells fill, so after many insertions a cell's blocks lie
!> anywhere in the pool and a query's cells cost a cache miss each (the head, then the block): at
!> 10^6 sand grains the query was a third of the run, mostly these misses. `reorder` lays the
!> blocks out again in cell order (level by level, cells in index order, each chain in its order):
!> a query's cells along x then lie side by side in memory. It changes no answer, nor the order of
!> the candidates. `neighbours` also reads the heads of up to 32 cells, then touches their first
!> blocks, before it tests any record: these loads do not wait for each other, so their cache
!> misses overlap (the million-grain job: 26 -> 19 s on 2 threads, same candidates in the same order).
!>
!> Usage:
!>     call new_cell_list(cl, box, periodic, rho_min)
!>     call cl%insert(i, center, rho, rin)
!>     call cl%reorder()                   ! now and then, after many insertions
!>     call cl%neighbours(center, rho, cand, shift, ncand, hit, rin=rin_q, jmin=j0)
!>     call cl%query(center, rho, centers, radii, cand, shift, ncand)
module anm_neighbours_cell_list
   use anm_core_kinds, only: wp, sp
   implicit none
   private

   public :: cell_list_type, new_cell_list

   integer, parameter :: max_cells_per_level = 2**24
   !> Records per block.
   integer, parameter :: block_size = 3

   !> What a query reads of a stored particle (40 bytes). No default values (nor in the block): a
   !> pool allocated ahead is then not written, and costs memory only as blocks are used.
   type :: cell_record_type
      !> Centre.
      real(wp) :: x(3)
      !> Bounding radius (rounded up) and certain-overlap radius (rounded down).
      real(sp) :: rho, rin
      !> Particle id.
      integer :: id
   end type cell_record_type

   !> Up to block_size records of one cell and the next block of the cell (128 bytes: the count
   !> and the first record share the first 48 bytes). `new_block` sets n and next; `insert` writes
   !> records 1..n.
   type :: cell_block_type
      integer :: n
      integer :: next
      type(cell_record_type) :: r(block_size)
   end type cell_block_type

   type :: cell_level_type
      real(wp) :: h(3) = 0.0_wp
      integer :: n(3) = 1
      real(wp) :: rho_max = 0.0_wp
      integer :: count = 0
      !> First block of each cell (0: empty).
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
      !> Block pool, nblock of them in use.
      type(cell_block_type), allocatable :: blocks(:)
      integer :: nblock = 0
   contains
      !> Insert particle i.
      procedure :: insert
      !> Remove particle i.
      procedure :: remove
      !> Room for a number of blocks without growing.
      procedure :: reserve
      !> Lay the blocks out again in cell order (memory locality of the queries).
      procedure :: reorder
      !> Particles whose bounding spheres (caller's arrays) intersect a query sphere.
      procedure :: query
      !> Candidates from the stored records, or the first certain overlap.
      procedure :: neighbours
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
      allocate (cl%blocks(max(16, cap / 2)))
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

   !> The cell (1-based index into the level's heads) of a centre in an active level.
   pure integer function cell_index(self, lv, center) result(cell)
      type(cell_list_type), intent(in) :: self
      type(cell_level_type), intent(in) :: lv
      real(wp), intent(in) :: center(3)
      integer :: c(3)
      c(1) = cell_coord(center(1), lv%h(1), lv%n(1), self%periodic)
      c(2) = cell_coord(center(2), lv%h(2), lv%n(2), self%periodic)
      c(3) = cell_coord(center(3), lv%h(3), lv%n(3), self%periodic)
      cell = 1 + c(1) + lv%n(1) * (c(2) + lv%n(2) * c(3))
   end function cell_index

   !> Insert particle i (ids must be inserted once each; the storage grows as needed).
   pure subroutine insert(self, i, center, rho, rin)
      !> Cell list.
      class(cell_list_type), intent(inout) :: self
      !> Particle id (>= 1).
      integer, intent(in) :: i
      !> Centre (inside the box).
      real(wp), intent(in) :: center(3)
      !> Bounding radius.
      real(wp), intent(in) :: rho
      !> Radius within which another particle certainly overlaps this one (see `neighbours`;
      !> default 0: never certain).
      real(wp), intent(in), optional :: rin
      integer :: k, cell, b, m, first
      k = level_for(self, rho)
      call activate(self, k)
      associate (lv => self%levels(k))
         cell = cell_index(self, lv, center)
         first = lv%head(cell)
         b = first
         if (first == 0) then
            call new_block(self, 0, b)
         else if (self%blocks(first)%n == block_size) then
            call new_block(self, first, b)
         end if
         lv%head(cell) = b
         associate (bk => self%blocks(b))
            bk%n = bk%n + 1
            m = bk%n
            bk%r(m)%x = center
            bk%r(m)%rho = round_up(rho)
            bk%r(m)%rin = 0.0_sp
            if (present(rin)) bk%r(m)%rin = round_down(rin)
            bk%r(m)%id = i
            lv%rho_max = max(lv%rho_max, real(bk%r(m)%rho, wp))
         end associate
         lv%count = lv%count + 1
      end associate
   end subroutine insert

   !> Remove the record of particle i, inserted with this centre and bounding radius (nothing
   !> happens when the cell holds no record of i). The last record of the cell's head block takes
   !> its place, so every block of a chain but the head stays full; a head block left empty leaves
   !> the chain (its room is reused after `reorder`). The order of the cell's records changes, the
   !> candidates of a query do not (the parking's tests depend on the candidates, not their
   !> order). The level's largest radius is not lowered: queries stay correct, a little wider.
   pure subroutine remove(self, i, center, rho)
      !> Cell list.
      class(cell_list_type), intent(inout) :: self
      !> Particle id.
      integer, intent(in) :: i
      !> Centre and bounding radius given at insertion.
      real(wp), intent(in) :: center(3), rho
      integer :: k, cell, b, m, first
      k = level_for(self, rho)
      if (.not. allocated(self%levels(k)%head)) return
      associate (lv => self%levels(k))
         cell = cell_index(self, lv, center)
         first = lv%head(cell)
         b = first
         do while (b > 0)
            do m = 1, self%blocks(b)%n
               if (self%blocks(b)%r(m)%id == i) then
                  associate (hd => self%blocks(first))
                     self%blocks(b)%r(m) = hd%r(hd%n)
                     hd%n = hd%n - 1
                     if (hd%n == 0) lv%head(cell) = hd%next
                  end associate
                  lv%count = lv%count - 1
                  return
               end if
            end do
            b = self%blocks(b)%next
         end do
      end associate
   end subroutine remove

   !> Make room for n blocks (nothing changes when there is room already). Blocks of the pool
   !> are not written before use, so room reserved ahead costs address space, not memory: a caller
   !> that knows about how many records will come (a block holds at least one) avoids the copies
   !> of a growing pool, which hold the old and the new pool at once.
   pure subroutine reserve(self, n)
      !> Cell list.
      class(cell_list_type), intent(inout) :: self
      !> Blocks.
      integer, intent(in) :: n
      if (n > size(self%blocks)) call resize_pool(self, n)
   end subroutine reserve

   !> Lay the blocks out again in cell order: level by level, cells in index order, the blocks of
   !> a cell's chain one after the other in chain order. Queries give the same candidates in the
   !> same order afterwards; the pool keeps its capacity (the old and the new pool exist at once
   !> during the copy).
   pure subroutine reorder(self)
      !> Cell list.
      class(cell_list_type), intent(inout) :: self
      type(cell_block_type), allocatable :: nb(:)
      integer :: k, cell, b, n
      allocate (nb(size(self%blocks)))
      n = 0
      do k = 1, size(self%levels)
         if (.not. allocated(self%levels(k)%head)) cycle
         do cell = 1, size(self%levels(k)%head)
            b = self%levels(k)%head(cell)
            if (b == 0) cycle
            self%levels(k)%head(cell) = n + 1
            do while (b > 0)
               n = n + 1
               nb(n) = self%blocks(b)
               b = self%blocks(b)%next
               nb(n)%next = 0
               if (b > 0) nb(n)%next = n + 1
            end do
         end do
      end do
      call move_alloc(nb, self%blocks)
      self%nblock = n
   end subroutine reorder

   !> A block pool of n (>= nblock) blocks.
   pure subroutine resize_pool(self, n)
      type(cell_list_type), intent(inout) :: self
      integer, intent(in) :: n
      type(cell_block_type), allocatable :: tmp(:)
      allocate (tmp(n))
      tmp(:self%nblock) = self%blocks(:self%nblock)
      call move_alloc(tmp, self%blocks)
   end subroutine resize_pool

   !> A new empty block whose chain continues with block `next`.
   pure subroutine new_block(self, next, nb)
      type(cell_list_type), intent(inout) :: self
      integer, intent(in) :: next
      integer, intent(out) :: nb
      integer :: m
      if (self%nblock == size(self%blocks)) then
         ! double; by a quarter beyond 2^20 blocks (128 MB), where the unused part of a doubling
         ! and the copy (old and new pool together) limit a run of 10^7 particles
         m = size(self%blocks)
         call resize_pool(self, merge(2 * m, m + m / 4, m < 2**20))
      end if
      self%nblock = self%nblock + 1
      nb = self%nblock
      self%blocks(nb)%n = 0
      self%blocks(nb)%next = next
   end subroutine new_block

   !> Particles j whose bounding spheres (centers(:, j), radii(j)) intersect the sphere
   !> (center, rho): cand(1:ncand) with shift(:, 1:ncand) such that the image of j that meets the
   !> query has centre centers(:, j) + shift. The arrays grow as needed. The order is
   !> deterministic: levels and cells in index order, in a cell the most recently inserted first.
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
      integer :: k, lo(3), hi(3), i1, i2, i3, c1, c2, c3, cell, j, s1, s2, s3, d3, b, m
      real(wp) :: reach, d(3), sh(3), lim, half(3)
      logical :: level_images, full(3)
      ncand = 0
      if (.not. allocated(cand)) allocate (cand(64), shift(3, 64))
      half = 0.5_wp * self%box
      do k = 1, size(self%levels)
         associate (lv => self%levels(k))
            if (lv%count == 0) cycle
            reach = rho + lv%rho_max
            call cell_range(self, lv, center, reach, lo, hi, full)
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
                     b = lv%head(cell)
                     do while (b > 0)
                        do m = self%blocks(b)%n, 1, -1
                           j = self%blocks(b)%r(m)%id
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
                                 sh(d3) = nearest_shift(d(d3), half(d3), self%box(d3))
                              end do
                              if (sum((d + sh)**2) < lim * lim) call push(cand, shift, ncand, j, sh)
                           else
                              if (sum(d**2) < lim * lim) call push(cand, shift, ncand, j, [0.0_wp, 0.0_wp, 0.0_wp])
                           end if
                        end do
                        b = self%blocks(b)%next
                     end do
                  end do
               end do
            end do
         end associate
      end do
   end subroutine query

   !> Candidates among the stored particles with jmin < id <= jmax (default: all) for an overlap
   !> test with a particle of bounding sphere (center, rho): cand(1:ncand) with image shifts
   !> shift(:, 1:ncand)
   !> (the image of j meeting the query has centre x_j + shift) whose stored bounding spheres
   !> intersect it. With `rin`, the search stops as soon as a stored particle j lies closer than
   !> rin + rin_j (the radii given to `insert`): then `hit` is true and the list is incomplete.
   !> Visiting order: levels from the coarsest; in a level the query's own cell first, then the
   !> cells outwards, nearer side first (so that a certain overlap is found early).
   pure subroutine neighbours(self, center, rho, cand, shift, ncand, hit, rin, jmin, jmax)
      !> Cell list.
      class(cell_list_type), intent(in) :: self
      !> Query centre (inside the box).
      real(wp), intent(in) :: center(3)
      !> Query bounding radius.
      real(wp), intent(in) :: rho
      !> Candidate ids.
      integer, allocatable, intent(inout) :: cand(:)
      !> Image shifts, (3, :).
      real(wp), allocatable, intent(inout) :: shift(:, :)
      !> Number of candidates.
      integer, intent(out) :: ncand
      !> A certain overlap was found.
      logical, intent(out) :: hit
      !> Radius of the query within which a stored particle's centre is a certain overlap, with the
      !> stored particle's own rin added.
      real(wp), intent(in), optional :: rin
      !> Only ids above jmin count.
      integer, intent(in), optional :: jmin
      !> Only ids up to jmax count.
      integer, intent(in), optional :: jmax
      integer :: k, lo(3), hi(3), own(3), side(3), na(3), nb(3), t1, t2, t3, i1, i2, i3, c1, c2, c3
      integer, parameter :: batch = 32
      integer :: s1, s2, s3, d3, b, m, j0, j1, nc, q, tot
      integer :: cells(batch), heads(batch), ims(3, batch)
      real(wp) :: reach, d(3), e(3), sh(3), csh(3), lim, half(3), qin, rr, r2
      logical :: level_images, full(3), anyfull, use_in
      ncand = 0
      hit = .false.
      if (.not. allocated(cand)) allocate (cand(64), shift(3, 64))
      half = 0.5_wp * self%box
      use_in = present(rin)
      qin = 0.0_wp
      if (use_in) qin = rin
      j0 = 0
      if (present(jmin)) j0 = jmin
      j1 = huge(1)
      if (present(jmax)) j1 = jmax
      do k = size(self%levels), 1, -1
         associate (lv => self%levels(k))
            if (lv%count == 0) cycle
            reach = rho + lv%rho_max
            level_images = self%periodic .and. any(2.0_wp * reach > self%box)
            call cell_range(self, lv, center, reach, lo, hi, full)
            anyfull = any(full)
            do d3 = 1, 3
               own(d3) = min(hi(d3), max(lo(d3), floor(center(d3) / lv%h(d3))))
               side(d3) = merge(1, -1, center(d3) - own(d3) * lv%h(d3) > 0.5_wp * lv%h(d3))
               na(d3) = merge(hi(d3) - own(d3), own(d3) - lo(d3), side(d3) > 0)
               nb(d3) = hi(d3) - lo(d3) - na(d3)
            end do
            ! the cells are visited in batches of up to `batch` cells: first every head of the
            ! batch is read, then the first block of every occupied cell is touched, then the
            ! records are tested. The loads of one step do not depend on each other, so the
            ! processor overlaps their cache misses instead of waiting for one cell at a time
            ! (the query is bound by memory latency at 10^6-10^7 particles). Same candidates in
            ! the same order as visiting cell by cell.
            nc = 0
            do t3 = 0, hi(3) - lo(3)
               i3 = zigzag(t3, own(3), side(3), na(3), nb(3))
               c3 = wrap_index(i3, lv%n(3))
               do t2 = 0, hi(2) - lo(2)
                  i2 = zigzag(t2, own(2), side(2), na(2), nb(2))
                  c2 = wrap_index(i2, lv%n(2))
                  do t1 = 0, hi(1) - lo(1)
                     i1 = zigzag(t1, own(1), side(1), na(1), nb(1))
                     c1 = wrap_index(i1, lv%n(1))
                     nc = nc + 1
                     cells(nc) = 1 + c1 + lv%n(1) * (c2 + lv%n(2) * c3)
                     ims(1, nc) = (i1 - c1) / lv%n(1)
                     ims(2, nc) = (i2 - c2) / lv%n(2)
                     ims(3, nc) = (i3 - c3) / lv%n(3)
                     if (nc == batch .or. (t1 == hi(1) - lo(1) .and. t2 == hi(2) - lo(2) &
                         .and. t3 == hi(3) - lo(3))) then
                        do q = 1, nc
                           heads(q) = lv%head(cells(q))
                        end do
                        tot = 0
                        do q = 1, nc
                           if (heads(q) > 0) tot = tot + self%blocks(heads(q))%n
                        end do
                        if (tot < 0) return ! never: it keeps the touching loads
                        do q = 1, nc
                           csh = real(ims(:, q), wp) * self%box
                           b = heads(q)
                           do while (b > 0)
                              associate (bk => self%blocks(b))
                                 do m = 1, bk%n
                                    if (bk%r(m)%id <= j0 .or. bk%r(m)%id > j1) cycle
                                    lim = rho + real(bk%r(m)%rho, wp)
                                    rr = qin + real(bk%r(m)%rin, wp)
                                    if (level_images) then
                                       d = bk%r(m)%x - center
                                       do s3 = -1, 1
                                          do s2 = -1, 1
                                             do s1 = -1, 1
                                                sh = [s1, s2, s3] * self%box
                                                r2 = sum((d + sh)**2)
                                                if (r2 >= lim * lim) cycle
                                                if (use_in .and. r2 < rr * rr .and. rr > 0.0_wp) then
                                                   hit = .true.
                                                   return
                                                end if
                                                call push(cand, shift, ncand, bk%r(m)%id, sh)
                                             end do
                                          end do
                                       end do
                                       cycle
                                    end if
                                    ! the cell's image gives the shift, except along edges
                                    ! whose whole range of cells is visited (there: the
                                    ! nearest image)
                                    sh = csh
                                    e = bk%r(m)%x - center
                                    if (anyfull) then
                                       do d3 = 1, 3
                                          if (full(d3)) sh(d3) = nearest_shift(e(d3), half(d3), &
                                                                               self%box(d3))
                                       end do
                                    end if
                                    d = e + sh
                                    r2 = d(1) * d(1) + d(2) * d(2) + d(3) * d(3)
                                    if (r2 >= lim * lim) cycle
                                    if (use_in .and. r2 < rr * rr .and. rr > 0.0_wp) then
                                       hit = .true.
                                       return
                                    end if
                                    call push(cand, shift, ncand, bk%r(m)%id, sh)
                                 end do
                                 b = bk%next
                              end associate
                           end do
                        end do
                        nc = 0
                     end if
                  end do
               end do
            end do
         end associate
      end do
   end subroutine neighbours

   !> Cells lo..hi (unwrapped indices) within `reach` of `center` in a level; `full` where the
   !> range covers every cell of a periodic edge (then 0..n-1).
   pure subroutine cell_range(self, lv, center, reach, lo, hi, full)
      type(cell_list_type), intent(in) :: self
      type(cell_level_type), intent(in) :: lv
      real(wp), intent(in) :: center(3), reach
      integer, intent(out) :: lo(3), hi(3)
      logical, intent(out) :: full(3)
      integer :: d3
      do d3 = 1, 3
         lo(d3) = floor((center(d3) - reach) / lv%h(d3))
         hi(d3) = floor((center(d3) + reach) / lv%h(d3))
         full(d3) = .false.
         if (self%periodic) then
            if (hi(d3) - lo(d3) + 1 >= lv%n(d3)) then
               lo(d3) = 0
               hi(d3) = lv%n(d3) - 1
               full(d3) = .true.
            end if
         else
            lo(d3) = max(0, lo(d3))
            hi(d3) = min(lv%n(d3) - 1, hi(d3))
         end if
      end do
   end subroutine cell_range

   !> The t-th (from 0) index of a range visited outwards from `own`: own, own + s, own - s,
   !> own + 2 s, ... where a cells lie on the side s and b on the other; once one side is used up
   !> the rest of the other follows.
   pure integer function zigzag(t, own, s, a, b) result(i)
      integer, intent(in) :: t, own, s, a, b
      integer :: mn
      mn = min(a, b)
      if (t <= 2 * mn) then
         i = own + merge(s, -s, mod(t, 2) == 1) * ((t + 1) / 2)
      else
         i = own + merge(s, -s, a > b) * (t - mn)
      end if
   end function zigzag

   !> Shift (0 or +-L) that brings a displacement d, |d| < L, to the nearest image.
   elemental real(wp) function nearest_shift(d, half, length) result(sh)
      real(wp), intent(in) :: d, half, length
      if (d > half) then
         sh = -length
      else if (d < -half) then
         sh = length
      else
         sh = 0.0_wp
      end if
   end function nearest_shift

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

   !> x in single precision, rounded up.
   elemental real(sp) function round_up(x) result(r)
      real(wp), intent(in) :: x
      r = real(x, sp)
      if (real(r, wp) < x) r = nearest(r, 1.0_sp)
   end function round_up

   !> x in single precision, rounded down.
   elemental real(sp) function round_down(x) result(r)
      real(wp), intent(in) :: x
      r = real(x, sp)
      if (real(r, wp) > x) r = nearest(r, -1.0_sp)
   end function round_down

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
end module anm_neighbours_cell_list
